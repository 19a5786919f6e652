"""`jaxdeploy simulate`'s reference cache: a stored reference comes back bit for bit, its key
changes with whatever the reference depends on (and not with the clearance joints' own
parameters), a failed reference is never stored, and the cache is off with the compilation
cache."""

import os

import numpy as np

from jaxdeploy.commands import _reference_cache as cache
from jaxdeploy.scenes import DeployArray


class _Run:
    def __init__(self, ok=True):
        rng = np.random.default_rng(0)
        self.ts = np.linspace(0.0, 2.0, 5)
        self.q, self.v, self.qdd = (rng.standard_normal((5, 9)) for _ in range(3))
        self.lam = rng.standard_normal((5, 8))
        self.ok = ok

    def status(self):
        return "ok" if self.ok else "failed after t = 1 s: max_steps_reached"


def test_stored_reference_comes_back_bit_for_bit(tmp_path, monkeypatch):
    monkeypatch.setenv("JAXDEPLOY_CACHE_DIR", str(tmp_path / "xla"))
    scene = DeployArray()
    params = scene.resolve_params()
    run = _Run()
    key = cache.key(scene, params, run.ts, scene.default_control)
    assert cache.load(key) is None
    events = {"lock_time": 0.5397921, "panel1_first_onset_time": float("nan")}
    cache.store(key, run, events)
    back = cache.load(key)
    for name in ("ts", "q", "v", "qdd", "lam"):
        np.testing.assert_array_equal(getattr(back, name), getattr(run, name))
    assert back.status() == "ok" and back.ok
    # The scene's events (the located lock time) too, NaN kept NaN.
    assert back.events["lock_time"] == events["lock_time"]
    assert np.isnan(back.events["panel1_first_onset_time"])


def test_key_follows_what_the_reference_depends_on(tmp_path, monkeypatch):
    monkeypatch.setenv("JAXDEPLOY_CACHE_DIR", str(tmp_path / "xla"))
    scene = DeployArray()
    params = scene.resolve_params()
    ts = np.linspace(0.0, 2.0, 2001)
    control = scene.default_control
    base = cache.key(scene, params, ts, control)
    # The clearance joints' own parameters do not change the ideal reference.
    assert cache.key(scene, {**params, "panel1_clearance": 2e-5}, ts, control) == base
    changed = [
        cache.key(scene, {**params, "latch_stiffness": 2 * params["latch_stiffness"]}, ts, control),
        cache.key(scene, params, ts[:-1], control),
        cache.key(scene, params, ts, control.replace(rtol=1e-8)),
        cache.key(DeployArray(latch="angle_only"), params, ts, control),
    ]
    assert base not in changed and len(set(changed)) == len(changed)


def test_failed_reference_is_not_stored_and_cache_off_stores_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("JAXDEPLOY_CACHE_DIR", str(tmp_path / "xla"))
    scene = DeployArray()
    params = scene.resolve_params()
    key = cache.key(scene, params, _Run().ts, scene.default_control)
    cache.store(key, _Run(ok=False), {})
    assert cache.load(key) is None
    monkeypatch.setenv("JAXDEPLOY_CACHE_DIR", "off")
    assert cache.folder() is None
    cache.store(key, _Run(), {})
    assert cache.load(key) is None


def test_an_edited_or_misplaced_reference_is_discarded_and_computed_again(
    tmp_path, monkeypatch, capsys
):
    """Issue 30: a stored reference whose numbers were edited was used without a warning (the
    headline deviations moved from 66 µm to 1056 µm). It records its key and a digest of its
    arrays; an entry that does not match is discarded with one line naming the cache."""
    monkeypatch.setenv("JAXDEPLOY_CACHE_DIR", str(tmp_path / "xla"))
    scene = DeployArray()
    params = scene.resolve_params()
    run = _Run()
    key = cache.key(scene, params, run.ts, scene.default_control)
    cache.store(key, run, {"lock_time": 0.5})
    path = tmp_path / "xla-references" / f"{key}.npz"
    with np.load(path) as data:
        stored = {k: data[k] for k in data.files}
    np.savez(path, **{**stored, "q": stored["q"] * 16})  # the numbers edited
    assert cache.load(key) is None
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "reference cache: discarding" in err and "digest" in err
    assert not path.exists()  # gone: the next run computes and stores it again

    other = cache.key(scene, {**params, "latch_stiffness": 1.0}, run.ts, scene.default_control)
    cache.store(other, run, {})
    os.replace(tmp_path / "xla-references" / f"{other}.npz", path)  # under the wrong key
    assert cache.load(key) is None
    assert "records another reference run's key" in capsys.readouterr().err
    cache.store(key, run, {})
    assert cache.load(key) is not None
