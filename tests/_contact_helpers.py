"""Helpers shared by the contact-law tests."""

import numpy as np


def central_difference(f, x, rel_step=1e-6, abs_step=1e-12):
    """Central finite difference of a scalar function at float x."""
    x = float(x)
    step = max(abs(x) * rel_step, abs_step)
    return (float(f(x + step)) - float(f(x - step))) / (2.0 * step)


def assert_grad_matches_fd(grad_value, f, x, rtol=1e-5, atol=0.0, **kw):
    fd = central_difference(f, x, **kw)
    assert np.isfinite(float(grad_value))
    np.testing.assert_allclose(float(grad_value), fd, rtol=rtol, atol=atol)
