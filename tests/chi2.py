"""χ² goodness-of-fit test of a direction sampler against the density it claims (the test Mitsuba 3 runs on every
BSDF and emitter, here for the fiber BCSDF and the environment light).

Directions are binned on a latitude–longitude grid of the sphere in the helper's own frame: latitude
θ = asin(d_0) ∈ [−π/2, π/2], longitude φ = atan2(d_2, d_1) ∈ [0, 2π) (a caller with another polar axis permutes
the components). The expected count of a cell is N ∫ pdf(ω) dω over it, integrated with ``sub`` × ``sub``
midpoint sub-cells (dω = cos θ dθ dφ); cells expecting fewer than ``min_expected`` samples are pooled into one
(Mitsuba's rule), and the p-value is that of Pearson's statistic with (cells − 1) degrees of freedom.
"""

import numpy as np
from scipy import stats


def direction_counts(samples, pdf, n_theta=24, n_phi=48, sub=12):
    """(observed, expected) counts per cell, flattened: ``samples`` (N, 3) unit directions, ``pdf`` a function of
    (M, 3) unit directions returning their solid-angle density (M,)."""
    samples = np.asarray(samples, float)
    theta = np.arcsin(np.clip(samples[:, 0], -1, 1))
    phi = np.mod(np.arctan2(samples[:, 2], samples[:, 1]), 2 * np.pi)
    observed, _, _ = np.histogram2d(theta, phi, bins=[n_theta, n_phi], range=[[-np.pi / 2, np.pi / 2], [0, 2 * np.pi]])
    dt, dp = np.pi / (n_theta * sub), 2 * np.pi / (n_phi * sub)
    t = -np.pi / 2 + dt * (np.arange(n_theta * sub) + 0.5)
    ph = dp * (np.arange(n_phi * sub) + 0.5)
    tt, pp = np.meshgrid(t, ph, indexing="ij")
    dirs = np.stack([np.sin(tt), np.cos(tt) * np.cos(pp), np.cos(tt) * np.sin(pp)], axis=-1).reshape(-1, 3)
    dens = np.asarray(pdf(dirs), float) * np.cos(tt.ravel())
    expected = dens.reshape(n_theta, sub, n_phi, sub).sum(axis=(1, 3)) * dt * dp * len(samples)
    return observed.ravel(), expected.ravel()


def pooled_pvalue(observed, expected, min_expected=5.0):
    """χ² p-value with the cells of expected count < ``min_expected`` pooled into one cell."""
    small = expected < min_expected
    obs = np.append(observed[~small], observed[small].sum())
    exp = np.append(expected[~small], expected[small].sum())
    keep = exp > 0
    obs, exp = obs[keep], exp[keep]
    exp *= obs.sum() / exp.sum()  # the pdf integrates to 1 up to quadrature error
    chi2 = ((obs - exp) ** 2 / exp).sum()
    return stats.chi2.sf(chi2, obs.size - 1)


def chi2_pvalue(samples, pdf, min_expected=5.0, **bins):
    """The p-value of ``samples`` drawn from ``pdf`` (``direction_counts``' arguments, then ``pooled_pvalue``)."""
    return pooled_pvalue(*direction_counts(samples, pdf, **bins), min_expected=min_expected)
