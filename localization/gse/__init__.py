"""Grassmann & Stiefel Eigenmaps (GSE) and the regression built on it.

- :class:`GrassmannStiefelEigenmaps`: the embedding ``r = h(Z)`` of the joint vectors
  ``Z = (w, theta)`` with its tangent frames (Grassmann kernel, Stiefel alignment);
- :class:`GSERegressor`: ``psi*`` (features -> pose), ``Phi*`` (pose -> features) and their
  Jacobians, the representation ``r*(w)`` / ``R*(theta)``, with the loop cut and the
  adaptive bandwidths;
- :func:`jacobian_regression`: Jacobian Regression, the kernel-weighted local fit of a map
  and its Jacobian.

The method as implemented here is in ``docs/method.md``.
"""

from localization.gse.embedding import GrassmannStiefelEigenmaps
from localization.gse.jacobian_regression import jacobian_regression
from localization.gse.regressor import GSERegressor

__all__ = ["GSERegressor", "GrassmannStiefelEigenmaps", "jacobian_regression"]
