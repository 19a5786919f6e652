"""`import jaxdeploy` gives the public API: every name in `__all__` resolves, lazily."""

import importlib
import inspect
import subprocess
import sys
import types

import jaxdeploy


def test_every_public_name_resolves_to_the_object_of_its_module():
    assert set(jaxdeploy.__all__) == {"__version__", *jaxdeploy._EXPORTS, *jaxdeploy._MODULES}
    assert len(jaxdeploy.__all__) == len(set(jaxdeploy.__all__))
    for name in jaxdeploy.__all__:
        value = getattr(jaxdeploy, name)
        assert value is not None, name
        if name in jaxdeploy._EXPORTS:
            assert value is getattr(importlib.import_module(jaxdeploy._EXPORTS[name]), name)
        assert name in dir(jaxdeploy)
    namespace = {}
    exec("from jaxdeploy import *", namespace)
    assert set(jaxdeploy.__all__) <= set(namespace)


def test_entry_points_of_the_module_exports():
    for name in jaxdeploy._MODULES:
        assert isinstance(getattr(jaxdeploy, name), types.ModuleType), name
    assert callable(jaxdeploy.fit.fit)
    assert callable(jaxdeploy.optimize.optimize)
    assert callable(jaxdeploy.sweep.sweep)
    assert inspect.isclass(jaxdeploy.get_scene("pendulum").__class__)
    assert set(jaxdeploy.SCENES) >= {"deploy_array", "slider_crank", "impact", "pendulum"}


def test_unknown_name_is_an_attribute_error():
    try:
        jaxdeploy.no_such_name  # noqa: B018
    except AttributeError as error:
        assert "no_such_name" in str(error)
    else:
        raise AssertionError("expected AttributeError")


def test_import_is_cheap_it_loads_no_simulation_code():
    """The lazy face imports nothing heavy until a name is used (a structural check, not a
    timing: the command-line help and `jaxdeploy --version` pay only for JAX)."""
    # _version and _xla_flags (the XLA flags set on import, before anything compiles) are
    # standard-library code only.
    code = (
        "import sys, jaxdeploy; "
        "print(sorted(m for m in sys.modules if m.startswith(('jaxdeploy.', 'diffrax', 'optax',"
        " 'equinox', 'optimistix')) and m not in ('jaxdeploy._version', 'jaxdeploy._xla_flags')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], check=True, capture_output=True, text=True
    ).stdout
    assert out.strip() == "[]", out
