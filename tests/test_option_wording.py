"""heli_cli.option_wording: a package error's Python arguments written as the running command's options."""

from __future__ import annotations

from heli_cli.option_wording import as_cli_options

OPTIONS = {"--segment", "--allow-damaged", "--episode-seconds", "--inputs"}


def test_a_python_argument_that_is_an_option_becomes_the_option():
    assert as_cli_options("pass episode_seconds=200 or less", "evaluate", OPTIONS) == \
        "pass --episode-seconds 200 or less"
    assert as_cli_options("use inputs='controller' (the PID sum)", "import", OPTIONS) == \
        "use --inputs controller (the PID sum)"
    assert as_cli_options("or segment=(3, 4.5)", "import", OPTIONS) == "or --segment 3:4.5"


def test_the_cli_hint_beside_it_is_said_once():
    assert as_cli_options("pass allow_damaged=True (heli import --allow-damaged) to import", "import", OPTIONS) == \
        "pass --allow-damaged to import"
    assert as_cli_options("pass segment='all' (heli import --segment all) or T0:T1", "import", OPTIONS) == \
        "pass --segment all or T0:T1"


def test_other_arguments_and_other_commands_hints_stay():
    assert as_cli_options("use render_mode='rgb_array'", "import", OPTIONS) == "use render_mode='rgb_array'"
    assert as_cli_options("pass segment='all' (heli identify --segment all)", "import", OPTIONS) == \
        "pass --segment all (heli identify --segment all)"
