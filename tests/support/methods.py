"""The classical methods' names shared by the registry and estimate tests."""

from __future__ import annotations


CLASSICAL = [
    "mlesac",
    "guided-mlesac",
    "prosac",
    "r-ransac",
    "waldsac",
    "lo-ransac",
    "preemptive",
    "usac",
    "inlier-detection",
]
