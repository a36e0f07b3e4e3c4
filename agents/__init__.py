"""Agents that navigate on the pose belief."""
