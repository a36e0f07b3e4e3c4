"""Baseline regressors features -> pose: kernel regression (KNR) and kNN retrieval.

``KernelRegressor`` is the seed paper's KNR baseline (section V, Table II):
Nadaraya-Watson with a Gaussian kernel and ONE global bandwidth for all output
coordinates, chosen by leave-one-out cross-validation. ``RetrievalRegressor``
is image retrieval: the pose of the k most similar training images
(``sklearn.neighbors.KNeighborsRegressor``).

Both follow scikit-learn conventions (hyper-parameters in ``__init__``, ``fit``
returns ``self``, fitted attributes end in ``_``, ``NotFittedError`` before
fit) and treat the output columns listed in ``periodic`` as angles: they are
averaged as (cos, sin) and returned through atan2, wrapped to (-pi, pi].
``save(path)`` / ``Class.load(path)`` store the training data and settings in an
``.npz`` (``allow_pickle=False``, settings as a JSON string).
"""

from localization.baselines.kernel import AUTO_NEIGHBORS, DENSE_LIMIT, KernelRegressor
from localization.baselines.retrieval import RetrievalRegressor

__all__ = ["AUTO_NEIGHBORS", "DENSE_LIMIT", "KernelRegressor", "RetrievalRegressor"]
