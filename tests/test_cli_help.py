"""Every command-line option's help states its default, and its unit where it has one
(issue 31, Deliver 4); the numbers the help texts name without importing JAX agree with the
package's."""

import argparse

import pytest

from jaxdeploy.commands import _args, discover

FLAGS = (argparse._StoreTrueAction, argparse._StoreFalseAction, argparse._HelpAction)


def _options():
    for module in discover():
        parser = argparse.ArgumentParser(prog=module.NAME)
        module.add_arguments(parser)
        for action in parser._actions:
            # Positional arguments and required options have no default to state; an on/off
            # flag is off unless given.
            if not action.option_strings or action.required or isinstance(action, FLAGS):
                continue
            yield module.NAME, action


@pytest.mark.parametrize("command, action", list(_options()), ids=lambda x: getattr(x, "dest", x))
def test_every_option_states_its_default_and_unit(command, action):
    text = action.help or ""
    flag = "/".join(action.option_strings)
    assert "default" in text.lower(), f"{command} {flag}: no default in its help: {text!r}"
    # A default shown as a Python name (e.g. a module constant) is not a number.
    assert "jaxdeploy." not in text.split("default")[-1][:40], f"{command} {flag}: {text!r}"
    unit = getattr(action.type, "unit", "")
    if unit:
        assert unit in text, f"{command} {flag}: unit {unit!r} missing from {text!r}"


def test_numbers_the_help_names_agree_with_the_package():
    from jaxdeploy.fit import RTOL_FLOOR
    from jaxdeploy.objectives import PRESETS
    from jaxdeploy.sweep import AUTO_EACH_CASES_PER_CORE, DEFAULT_CHUNK_SIZE

    assert _args.SWEEP_CHUNK_SIZE == DEFAULT_CHUNK_SIZE
    assert _args.SWEEP_AUTO_EACH_CASES_PER_CORE == AUTO_EACH_CASES_PER_CORE
    assert tuple(_args.OBJECTIVE_PRESETS) == tuple(PRESETS)
    assert _args.RTOL_FLOOR == RTOL_FLOOR


def test_sweep_help_lists_the_objective_presets_and_fit_help_its_tolerance_rule(capsys):
    from jaxdeploy.cli import main

    assert main(["sweep", "--help"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in _args.OBJECTIVE_PRESETS)
    assert main(["fit", "--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "chooses the model's tolerance itself" in out


def test_numbers_in_messages_print_as_numbers():
    import numpy as np

    from jaxdeploy._validation import check_range

    with pytest.raises(ValueError) as refused:
        check_range("clearance", np.float64(0.00108), 0.0, 1e-3, unit="m")
    message = str(refused.value)
    assert "clearance = 0.00108 m is invalid" in message and "np.float64" not in message
