"""Localization toolkit: features, GSE regression, baselines, intrinsic dimension, EKF."""
