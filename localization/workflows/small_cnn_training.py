"""Train the self-supervised SmallCNN feature extractor on images of many cities (a
developers' job: ``python scripts/train_small_cnn.py``, a thin script over
:func:`train_small_cnn_job`), e.g.::

    python scripts/train_small_cnn.py --city-seeds 100-119 --images-per-city 500 --epochs 12

(10,000 images; about 10 min on 1 CPU thread for the default pose-contrastive objective.)

The evaluation city must not be among the training cities: ``--eval-seed`` (default 0) is
checked and refused. Writes ``<out>`` (``torch.load(weights_only=True)``-loadable checkpoint,
use as ``SmallCNNFeatures(weights=<out>)``) and ``<out>.json`` (args, loss history, timing).
``--synthetic`` trains on generated images instead of the env (a smoke test without MuJoCo).
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from localization.features.small_cnn import save_small_cnn, train_small_cnn

__all__ = ["SmallCNNTrainConfig", "parse_seeds", "synthetic_images", "train_small_cnn_job"]


@dataclass
class SmallCNNTrainConfig:
    """Settings of the SmallCNN training (the options of ``scripts/train_small_cnn.py``)."""

    city_seeds: str = field(default="100-119", metadata={
        "help": "scene seeds of the training cities: 'a-b' (inclusive) or 'a,b,c'"})
    eval_seed: int = field(default=0, metadata={
        "help": "scene seed of the evaluation city; refused if among --city-seeds"})
    images_per_city: int = field(default=500, metadata={"help": "images collected per city"})
    mode: str = field(default="random", metadata={
        "help": "envs.collect_dataset mode: grid, random, route, lanes or coverage"})
    camera: str = field(default="perspective", metadata={"help": "env camera"})
    conditions: str = field(default="default", metadata={
        "help": "AppearanceNav-v0 conditions of the training images: a preset, or 'random' "
                "(every image its own lighting, weather and camera effects: features that "
                "carry across conditions)"})
    looks_per_pose: int = field(default=1, metadata={
        "help": "with --conditions random: render every pose this many times, each in its own "
                "look (the copies are each other's nearest poses: pose_contrastive positives "
                "under other lighting and weather)"})
    n_neighbors: int = field(default=4, metadata={
        "help": "pose_contrastive: positives drawn from this many pose-nearest images"})
    image_size: int = field(default=64, metadata={"help": "rendered image side (pixels)"})
    objective: str = field(default="pose_contrastive", metadata={
        "help": "self-supervised objective: autoencoder, contrastive or pose_contrastive "
                "(positives = pose-nearest images of the same city, e.g. neighbouring route "
                "frames)"})
    embedding_dim: int = field(default=128, metadata={"help": "CNN embedding dimension"})
    width: int = field(default=32, metadata={"help": "channels of the first conv layer"})
    epochs: int = field(default=12, metadata={"help": "training epochs"})
    batch_size: int = field(default=128, metadata={"help": "training batch size"})
    lr: float = field(default=1e-3, metadata={"help": "Adam learning rate (cosine schedule)"})
    seed: int = field(default=1, metadata={
        "help": "seed of training (init, shuffling, augmentation) and of data collection"})
    num_threads: int = field(default=2, metadata={"help": "torch threads"})
    out: str = field(default="results/small_cnn.pt", metadata={"help": "checkpoint path"})
    synthetic: bool = field(default=False, metadata={
        "help": "train on synthetic images (no env needed), for smoke tests"})


def parse_seeds(text: str) -> list[int]:
    """'100-119' -> [100, ..., 119]; '1,5,7' -> [1, 5, 7]."""
    seeds: list[int] = []
    for part in text.split(","):
        if "-" in part.strip()[1:]:
            a, b = part.split("-", 1)
            seeds.extend(range(int(a), int(b) + 1))
        elif part.strip():
            seeds.append(int(part))
    return seeds


def synthetic_images(n: int, size: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Crops of smooth random colour panoramas (n, size, size, 3) uint8, and fake poses (n, 3)
    (x = crop offset / 10, one panorama per "city" of 50 images)."""
    rng = np.random.default_rng(seed)
    width = 4 * size
    xs = np.arange(width)[:, None] / width
    out = np.empty((n, size, size, 3), dtype=np.uint8)
    poses = np.zeros((n, 3))
    for k in range(0, n, 50):
        freqs = rng.integers(1, 8, size=(6, 1))
        phase = rng.uniform(0, 2 * np.pi, size=(6, 3))
        pano = 0.5 + 0.08 * np.sin(2 * np.pi * freqs[None] * xs[..., None] + phase[None]).sum(1)
        rows = np.linspace(0.6, 1.2, size)[:, None, None]
        img = np.clip(rows * pano[None], 0, 1)
        for j in range(k, min(k + 50, n)):
            x0 = rng.integers(0, width - size)
            out[j] = (255 * img[:, x0:x0 + size]).astype(np.uint8)
            poses[j] = (x0 / 10, k, 0.0)
    return out, poses


def other_looks(env: object, images: np.ndarray, poses: np.ndarray, looks: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """``images`` (n, H, W, 3) and ``looks - 1`` more renders of each pose, each in the next
    look of the env's randomised conditions: (n * looks, H, W, 3) and their poses."""
    if looks <= 1:
        return images, poses
    base = env.unwrapped
    extra = np.empty((looks - 1, *images.shape), np.uint8)
    for i, pose in enumerate(poses):
        base.set_pose(pose)
        for j in range(looks - 1):
            base.set_conditions()
            extra[j, i] = base.render_camera()
    return (np.concatenate([images, extra.reshape(-1, *images.shape[1:])]),
            np.tile(poses, (looks, 1)))


def collect(args: SmallCNNTrainConfig, seeds: list[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Images, poses and city seeds from ``gymnasium.make("AppearanceNav-v0", scene_seed=s)``."""
    import gymnasium as gym

    import envs

    batches, all_poses, groups = [], [], []
    for i, s in enumerate(seeds):
        env = gym.make("AppearanceNav-v0", scene_seed=s, camera=args.camera,
                       conditions=args.conditions,
                       image_size=(args.image_size, args.image_size))
        try:
            images, poses = envs.collect_dataset(env, args.images_per_city, args.mode,
                                                 args.seed * 100_003 + s)
            images, poses = other_looks(env, images, poses, args.looks_per_pose)
        finally:
            env.close()
        batches.append(np.asarray(images, dtype=np.uint8))
        all_poses.append(np.asarray(poses, dtype=np.float64))
        groups.append(np.full(len(images), s))
        print(f"city {s}: {len(images)} images ({i + 1}/{len(seeds)})", flush=True)
    return np.concatenate(batches), np.concatenate(all_poses), np.concatenate(groups)


def train_small_cnn_job(args: SmallCNNTrainConfig, command: str = "") -> Path:
    """Collect (or generate) the images, train, save the checkpoint and ``<out>.json``
    (``command``, the command line that ran it, is recorded there); returns the checkpoint.

    Raises
    ------
    ValueError
        If the evaluation city is among the training cities.
    """
    seeds = parse_seeds(args.city_seeds)
    if args.looks_per_pose < 1:
        raise ValueError(f"looks_per_pose must be >= 1, got {args.looks_per_pose}")
    if args.looks_per_pose > 1 and args.conditions != "random":
        raise ValueError(f"looks_per_pose={args.looks_per_pose} renders each pose in several "
                         f"looks and needs conditions='random', got {args.conditions!r}")
    if args.eval_seed in seeds:
        raise ValueError(f"eval_seed: the eval city {args.eval_seed} is among the training "
                         f"cities {seeds}")
    t0 = time.perf_counter()
    if args.synthetic:
        images, poses = synthetic_images(args.images_per_city * len(seeds), args.image_size,
                                         args.seed)
        groups = poses[:, 1].astype(int)
    else:
        images, poses, groups = collect(args, seeds)
    t_collect = time.perf_counter() - t0
    model = train_small_cnn(images, args.epochs, args.seed, objective=args.objective,
                            embedding_dim=args.embedding_dim, width=args.width,
                            input_size=args.image_size, batch_size=args.batch_size, lr=args.lr,
                            poses=poses, groups=groups, n_neighbors=args.n_neighbors,
                            num_threads=args.num_threads)
    t_train = time.perf_counter() - t0 - t_collect
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    save_small_cnn(model, out)
    meta = {"command": command.strip(), "args": dataclasses.asdict(args), "seeds": seeds,
            "n_images": len(images), "torch": torch.__version__,
            "loss_history": model.loss_history, "collect_s": t_collect, "train_s": t_train}
    out.with_suffix(out.suffix + ".json").write_text(json.dumps(meta, indent=2))
    print(f"saved {out}: {len(images)} images, loss {model.loss_history[0]:.4f} -> "
          f"{model.loss_history[-1]:.4f}, collect {t_collect:.0f}s, train {t_train:.0f}s")
    return out

