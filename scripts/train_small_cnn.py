"""Train the SmallCNN feature extractor on other cities (a developers' job; what it does and
writes: :mod:`localization.workflows.small_cnn_training`)."""

import sys

from localization.cli._args import parse_dataclass_args
from localization.workflows import small_cnn_training as job

if __name__ == "__main__":
    args = parse_dataclass_args(job.SmallCNNTrainConfig, job.__doc__)
    try:
        job.train_small_cnn_job(args, "python scripts/train_small_cnn.py " + " ".join(sys.argv[1:]))
    except ValueError as err:
        raise SystemExit(f"error: {err}") from None
