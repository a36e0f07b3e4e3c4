"""A small self-supervised CNN as visual features omega(X) (64 x 64 input, ~0.3 M parameters).

Encoder: four 3x3 stride-2 conv + batch-norm + ReLU layers (64 -> 32 -> 16 -> 8 -> 4 pixels), then
a linear map of the flattened 4 x 4 map to an ``embedding_dim`` vector. Flattening, rather than
global pooling, keeps *where* things are in the image, which is what a pose regressor needs.

Self-supervised objectives (:func:`train_small_cnn`), all with photometric augmentation
(brightness, contrast, per-channel gain) so that features ignore lighting:

- ``"autoencoder"`` (default): a denoising autoencoder; the decoder reconstructs the clean image
  from the embedding of the augmented one (MSE). Reconstruction keeps all appearance information
  and is smooth in the input, so nearby poses give nearby features.
- ``"contrastive"``: SimCLR-style NT-Xent between two augmented views of an image, whose
  augmentations also include random shifts of up to ``max_shift`` pixels.
- ``"pose_contrastive"``: NT-Xent where the positive of an image is one of its
  ``n_neighbors`` nearest images *in pose* within the same city (``poses``, ``groups``); with
  route data these are the neighbouring frames. Needs poses of the training cities only.

Train it on images of *other* cities (``scripts/train_small_cnn.py``, never the evaluation city)
and pass the saved file as ``SmallCNNFeatures(weights=path)``.

Measured once (cities 100-119, 500 random views each, 12 epochs; evaluated on city 0 with 3000
random 64x64 views as the map, 300 as queries, 5-NN pose regression on 64 PCA components):
pose-contrastive position RMSE 1.8 m / median yaw error 6 deg / 84 % of nearest neighbours
within 2 m and 30 deg, against 6.1 m / 27 deg / 36 % for the autoencoder, 5.6 m / 22 deg / 42 %
for PixelPCA and 6.9 m / 39 deg / 31 % for ImageNet EfficientNet-Lite0.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from scipy.spatial import KDTree
from torch import nn

from localization.features._pca import fit_pca, pca_from_state, pca_state
from localization.features.base import FeatureExtractor, batched, check_images, torch_threads

__all__ = ["SmallCNN", "SmallCNNFeatures", "load_small_cnn", "save_small_cnn", "train_small_cnn"]

OBJECTIVES = ("autoencoder", "contrastive", "pose_contrastive")


def _conv(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(cin, cout, 3, stride=2, padding=1, bias=False),
                         nn.BatchNorm2d(cout), nn.ReLU(inplace=True))


def _deconv(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(nn.ConvTranspose2d(cin, cout, 4, stride=2, padding=1, bias=False),
                         nn.BatchNorm2d(cout), nn.ReLU(inplace=True))


class SmallCNN(nn.Module):
    """Encoder (+ decoder or projection head for training).

    Parameters
    ----------
    embedding_dim : int
        Dimension of the features returned by :meth:`embed`.
    width : int
        Channels of the first conv layer (then 2w, 4w, 2w).
    input_size : int
        Square input side; images are resized to it. Must be divisible by 16.
    objective : {"autoencoder", "contrastive", "pose_contrastive"}
        Which training head to build.
    """

    def __init__(self, embedding_dim: int = 128, width: int = 32, input_size: int = 64,
                 objective: str = "autoencoder") -> None:
        super().__init__()
        if objective not in OBJECTIVES:
            raise ValueError(f"unknown objective {objective!r}; choose one of {OBJECTIVES}")
        if input_size % 16:
            raise ValueError(f"input_size must be divisible by 16, got {input_size}")
        self.config = {"embedding_dim": int(embedding_dim), "width": int(width),
                       "input_size": int(input_size), "objective": objective}
        w, s = int(width), input_size // 16
        self._grid = (2 * w, s, s)
        self.encoder = nn.Sequential(_conv(3, w), _conv(w, 2 * w), _conv(2 * w, 4 * w),
                                     _conv(4 * w, 2 * w), nn.Flatten(),
                                     nn.Linear(2 * w * s * s, embedding_dim))
        if objective == "autoencoder":
            self.head = nn.Sequential(nn.Linear(embedding_dim, 2 * w * s * s), nn.ReLU(),
                                      nn.Unflatten(1, self._grid), _deconv(2 * w, 4 * w),
                                      _deconv(4 * w, 2 * w), _deconv(2 * w, w),
                                      nn.ConvTranspose2d(w, 3, 4, stride=2, padding=1))
        else:
            self.head = nn.Sequential(nn.Linear(embedding_dim, embedding_dim), nn.ReLU(),
                                      nn.Linear(embedding_dim, 64))
        self.loss_history: list[float] = []

    @property
    def input_size(self) -> int:
        return int(self.config["input_size"])

    def embed(self, x: torch.Tensor) -> torch.Tensor:
        """Normalised float images (n, 3, S, S) -> embeddings (n, embedding_dim)."""
        return self.encoder(x)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Training head output: reconstruction (n, 3, S, S) or projection (n, 64)."""
        return self.head(self.embed(x))


def to_input(images: torch.Tensor, size: int) -> torch.Tensor:
    """uint8 (n, H, W, 3) -> float32 (n, 3, size, size), values (x/255 - 0.5) / 0.25."""
    x = images.permute(0, 3, 1, 2).to(torch.float32) / 255.0
    if tuple(x.shape[-2:]) != (size, size):
        x = F.interpolate(x, size=(size, size), mode="bilinear", antialias=True,
                          align_corners=False)
    return (x - 0.5) / 0.25


def augment(x: torch.Tensor, gen: torch.Generator, max_shift: int = 0,
            strength: float = 0.2) -> torch.Tensor:
    """Photometric jitter (brightness, contrast, channel gain) and random integer shifts.

    ``x`` is a normalised batch (n, 3, S, S) from :func:`to_input`; returns the same shape.
    """
    n = x.shape[0]

    def u(*shape: int) -> torch.Tensor:
        return (torch.rand(*shape, generator=gen) * 2 - 1) * strength

    img = x * 0.25 + 0.5  # back to [0, 1]
    mean = img.mean(dim=(1, 2, 3), keepdim=True)
    img = (img - mean) * (1 + u(n, 1, 1, 1)) + mean  # contrast
    img = img * (1 + u(n, 1, 1, 1)) * (1 + 0.5 * u(n, 3, 1, 1))  # brightness, colour gain
    img = img.clamp(0.0, 1.0)
    if max_shift > 0:
        pad = F.pad(img, [max_shift] * 4, mode="replicate")
        s = img.shape[-1]
        offs = torch.randint(0, 2 * max_shift + 1, (n, 2), generator=gen)
        img = torch.stack([pad[i, :, dy:dy + s, dx:dx + s]
                           for i, (dy, dx) in enumerate(offs.tolist())])
    return (img - 0.5) / 0.25


def nt_xent(z1: torch.Tensor, z2: torch.Tensor, temperature: float) -> torch.Tensor:
    """SimCLR loss of two views (n, d): each sample's positive is its other view."""
    z = F.normalize(torch.cat([z1, z2]), dim=1)
    sim = z @ z.T / temperature
    sim.fill_diagonal_(float("-inf"))
    n = z1.shape[0]
    target = torch.cat([torch.arange(n, 2 * n), torch.arange(0, n)])
    return F.cross_entropy(sim, target)


def pose_neighbors(poses: np.ndarray, groups: np.ndarray | None, k: int,
                   yaw_scale: float = 2.0) -> np.ndarray:
    """Indices (n, k) of each pose's k nearest other poses of the same group.

    Distance: Euclidean on ``[x, y, yaw_scale * cos(yaw), yaw_scale * sin(yaw)]`` (metres; a
    heading change of 1 rad counts about ``yaw_scale`` m).
    """
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] != 3 or not np.all(np.isfinite(poses)):
        raise ValueError(f"poses must be finite (n, 3) [x, y, yaw], got shape {poses.shape}")
    groups = np.zeros(len(poses), int) if groups is None else np.asarray(groups)
    if groups.shape != (len(poses),):
        raise ValueError(f"groups must have shape ({len(poses)},), got {groups.shape}")
    emb = np.c_[poses[:, :2], yaw_scale * np.cos(poses[:, 2]), yaw_scale * np.sin(poses[:, 2])]
    out = np.empty((len(poses), k), dtype=np.int64)
    for g in np.unique(groups):
        idx = np.flatnonzero(groups == g)
        if len(idx) <= k:
            raise ValueError(f"group {g} has {len(idx)} images; need more than n_neighbors={k}")
        _, nb = KDTree(emb[idx]).query(emb[idx], k=k + 1)
        out[idx] = idx[nb[:, 1:]]  # column 0 is the point itself
    return out


def train_small_cnn(images: np.ndarray, epochs: int = 20, seed: int = 0, *,
                    objective: str = "autoencoder", embedding_dim: int = 128, width: int = 32,
                    input_size: int = 64, batch_size: int = 128, lr: float = 1e-3,
                    max_shift: int = 2, temperature: float = 0.2,
                    poses: np.ndarray | None = None, groups: np.ndarray | None = None,
                    n_neighbors: int = 4, num_threads: int | None = None,
                    progress: bool = True) -> SmallCNN:
    """Train a :class:`SmallCNN` self-supervised on uint8 images (n, H, W, 3).

    ``poses`` (n, 3) and ``groups`` (n,) (e.g. the city seed of each image) are used by
    ``objective="pose_contrastive"`` only (see :func:`pose_neighbors`). Deterministic for a
    given ``seed`` (weights init, shuffling and augmentation all draw from seeded generators).
    Adam with a cosine learning-rate schedule. The per-epoch mean loss is in
    ``model.loss_history``. Returns the model in eval mode.
    """
    images = check_images(images)
    if len(images) < 2:
        raise ValueError(f"need at least 2 images to train, got {len(images)}")
    nbrs = None
    if objective == "pose_contrastive":
        if poses is None or len(poses) != len(images):
            raise ValueError("objective 'pose_contrastive' needs poses (n, 3) for the n images "
                             "(SmallCNNFeatures: fit(images, poses))")
        nbrs = torch.from_numpy(pose_neighbors(poses, groups, n_neighbors))
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    model = SmallCNN(embedding_dim, width, input_size, objective)
    data = torch.from_numpy(np.ascontiguousarray(images))
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    steps_per_epoch = -(-len(data) // batch_size)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, max(1, epochs * steps_per_epoch))
    from tqdm.auto import trange

    with torch_threads(num_threads):
        model.train()
        bar = trange(epochs, desc=f"small_cnn {objective}", disable=not progress)
        for _ in bar:
            perm, total = torch.randperm(len(data), generator=gen), 0.0
            for s in range(0, len(data), batch_size):
                idx = perm[s:s + batch_size]
                if len(idx) < 2:
                    continue  # batch norm / contrastive need >= 2 samples
                x = to_input(data[idx], input_size)
                if objective == "autoencoder":
                    loss = F.mse_loss(model(augment(x, gen)), x)
                elif nbrs is not None:
                    pos = nbrs[idx, torch.randint(0, nbrs.shape[1], (len(idx),), generator=gen)]
                    xp = to_input(data[pos], input_size)
                    loss = nt_xent(model(augment(x, gen, max_shift)),
                                   model(augment(xp, gen, max_shift)), temperature)
                else:
                    loss = nt_xent(model(augment(x, gen, max_shift)),
                                   model(augment(x, gen, max_shift)), temperature)
                opt.zero_grad(set_to_none=True)
                loss.backward()
                opt.step()
                sched.step()
                total += loss.item() * len(idx)
            model.loss_history.append(total / len(data))
            bar.set_postfix(loss=f"{model.loss_history[-1]:.4f}")
    return model.eval()


def save_small_cnn(model: SmallCNN, path: str | Path) -> None:
    """Save config + state dict (tensors only) for ``torch.load(weights_only=True)``."""
    torch.save({"config": dict(model.config), "state_dict": model.state_dict(),
                "loss_history": list(model.loss_history)}, path)


def network_digest(model: nn.Module) -> str:
    """SHA-256 of a network's configuration (if any) and weights: equal digests, equal
    outputs."""
    h = hashlib.sha256(json.dumps(getattr(model, "config", {}), sort_keys=True).encode())
    for name, value in model.state_dict().items():
        h.update(name.encode())
        h.update(np.ascontiguousarray(value.detach().cpu().numpy()).tobytes())
    return h.hexdigest()


def load_small_cnn(path: str | Path) -> SmallCNN:
    """Load a model written by :func:`save_small_cnn` (eval mode, strict)."""
    ckpt = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(ckpt, dict) or "config" not in ckpt or "state_dict" not in ckpt:
        raise ValueError(f"{path} is not a SmallCNN checkpoint (needs 'config' and 'state_dict')")
    model = SmallCNN(**ckpt["config"])
    model.load_state_dict(ckpt["state_dict"], strict=True)
    model.loss_history = [float(v) for v in ckpt.get("loss_history", [])]
    return model.eval()


class SmallCNNFeatures(FeatureExtractor):
    """Embeddings of a small self-supervised CNN, optionally PCA-reduced.

    Parameters
    ----------
    n_components : int or None
        PCA dimension fitted in ``fit`` (clipped to the embedding dimension); None keeps the raw
        ``embedding_dim`` embedding.
    weights : str or None
        Checkpoint from :func:`save_small_cnn` (e.g. by ``scripts/train_small_cnn.py`` on other
        cities). None: ``fit(images, poses=None)`` trains the CNN on the images it is given,
        with the settings below (``objective="pose_contrastive"`` needs the poses as ``y``).
    embedding_dim, width, input_size, objective, epochs, batch_size, lr, seed
        Passed to :func:`train_small_cnn` when ``weights`` is None.
    num_threads : int or None
        ``torch.set_num_threads`` during training/inference (restored afterwards).
    progress : bool
        Show tqdm bars.
    random_state : int or None
        Seed of the PCA.

    Attributes
    ----------
    model_ : SmallCNN
    pca_ : PCA or None
    image_shape_ : tuple of int
    """

    name = "small_cnn"

    def __init__(self, n_components: int | None = 64, weights: str | None = None,
                 embedding_dim: int = 128, width: int = 32, input_size: int = 64,
                 objective: str = "autoencoder", epochs: int = 20, batch_size: int = 128,
                 lr: float = 1e-3, seed: int = 0, num_threads: int | None = None,
                 progress: bool = True, random_state: int | None = 0) -> None:
        self.n_components = n_components
        self.weights = weights
        self.embedding_dim = embedding_dim
        self.width = width
        self.input_size = input_size
        self.objective = objective
        self.epochs = epochs
        self.batch_size = batch_size
        self.lr = lr
        self.seed = seed
        self.num_threads = num_threads
        self.progress = progress
        self.random_state = random_state

    def embeddings(self, images: np.ndarray) -> np.ndarray:
        """Raw CNN embeddings (n, embedding_dim) float64 of uint8 images (no PCA)."""
        images = check_images(images)
        model = self.model_
        out = np.empty((len(images), model.config["embedding_dim"]), dtype=np.float64)
        with torch_threads(self.num_threads), torch.inference_mode():
            for sl in batched(len(images), 256, self.progress, "small_cnn"):
                x = to_input(torch.from_numpy(np.ascontiguousarray(images[sl])),
                             model.input_size)
                out[sl] = model.embed(x).double().numpy()
        return out

    def _fit(self, images: np.ndarray, y: Any = None) -> np.ndarray:
        if self.weights is None:
            self.model_ = train_small_cnn(
                images, self.epochs, self.seed, objective=self.objective,
                embedding_dim=self.embedding_dim, width=self.width, input_size=self.input_size,
                batch_size=self.batch_size, lr=self.lr, poses=y, num_threads=self.num_threads,
                progress=self.progress)
        else:
            self.model_ = load_small_cnn(self.weights)
        self._stage_key = None
        emb = self.embeddings(images)
        self.pca_ = None
        if self.n_components is not None:
            self.pca_ = fit_pca(emb, int(self.n_components), False, self.random_state)
        return emb if self.pca_ is None else self.pca_.transform(emb)

    def _transform(self, images: np.ndarray) -> np.ndarray:
        return self._head(self._embed(images))

    def stage_key(self) -> str:
        """A digest of the CNN (its configuration and weights): extractors with the same
        network share its embeddings; each keeps its own PCA."""
        self._check_fitted()
        if getattr(self, "_stage_key", None) is None:
            self._stage_key = network_digest(self.model_)
        return self._stage_key

    def _embed(self, images: np.ndarray) -> np.ndarray:
        return self.embeddings(images)

    def _head(self, embedded: np.ndarray) -> np.ndarray:
        emb = np.asarray(embedded, dtype=np.float64)
        if emb.ndim != 2 or emb.shape[1] != self.model_.config["embedding_dim"]:
            raise ValueError(f"embedded must be CNN embeddings (n, "
                             f"{self.model_.config['embedding_dim']}), got {emb.shape}")
        return emb if self.pca_ is None else self.pca_.transform(emb)

    def _state_arrays(self) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {"cnn_config": np.array(json.dumps(self.model_.config))}
        for k, v in self.model_.state_dict().items():
            out["cnn/" + k] = v.detach().cpu().numpy().copy()
        return {**out, **pca_state(self.pca_)}

    def _load_arrays(self, state: dict[str, Any]) -> None:
        config = json.loads(str(np.asarray(state["cnn_config"])[()]))
        model = SmallCNN(**config)
        sd = {k[4:]: torch.from_numpy(np.array(v)) for k, v in state.items()
              if k.startswith("cnn/")}
        model.load_state_dict(sd, strict=True)
        self.model_ = model.eval()
        self._stage_key = None
        self.pca_ = pca_from_state(state, whiten=False)

    def _n_out(self) -> int:
        return (int(self.model_.config["embedding_dim"]) if self.pca_ is None
                else int(self.pca_.n_components_))
