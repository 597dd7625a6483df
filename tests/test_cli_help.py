"""Help, --version and docs/cli.md: every command and option documented, no raw reST, the exit
codes and the physically known parameters in the docs as the code has them."""

import argparse
import os
import pathlib
import re
import subprocess
import sys

import pytest

from appearance_jax import registry
from appearance_jax.cli import EXIT_CODES, EXIT_USAGE, build_parser, main
from appearance_jax.cli import known
from appearance_jax.cli.parser import COMMANDS, version

DOC = pathlib.Path(__file__).resolve().parents[1] / "docs" / "cli.md"


def _subparsers(parser):
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return action


def _help(argv, capsys):
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 0
    return capsys.readouterr().out


def test_top_level_help_has_examples_and_no_raw_rest(capsys):
    text = _help(["-h"], capsys)
    assert "``" not in text and "::" not in text and ":func:" not in text
    examples = text.split("examples:")[1].split("exit status:")[0]
    assert len(re.findall(r"^  appearance-jax ", examples, flags=re.M)) == 2
    for code in EXIT_CODES:
        assert re.search(rf"^  {code}  ", text, flags=re.M), code
    for name in _subparsers(build_parser()).choices:
        assert name in text


@pytest.mark.parametrize("name", list(_subparsers(build_parser()).choices))
def test_every_subcommand_has_help(name, capsys):
    text = _help([name, "-h"], capsys)
    assert f"usage: appearance-jax {name}" in text and "``" not in text


def test_every_command_and_option_has_a_help_string():
    top = build_parser()
    for action in top._actions:
        assert action.help, f"appearance-jax {action.option_strings or action.dest} has no help"
    sub = _subparsers(top)
    helped = {a.dest: a.help for a in sub._choices_actions}
    for name, parser in sub.choices.items():
        assert helped.get(name), f"command {name} has no help line"
        for action in parser._actions:
            assert action.help, f"{name}: option {action.option_strings or action.dest} has no help"


def test_version(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--version"])
    assert e.value.code == 0
    out = capsys.readouterr().out.strip()
    assert out == f"appearance-jax {version()}" and re.fullmatch(r"\d+\.\d+.*", version())


def test_docs_list_every_command_option_and_exit_code():
    doc = DOC.read_text()
    sub = _subparsers(build_parser())
    own = {m.NAME for m in COMMANDS if m.__name__.startswith("appearance_jax.cli.")}
    for name, parser in sub.choices.items():
        assert f"## `appearance-jax {name}" in doc, name
        if name not in own:  # a command of another package (export) is documented in its own page
            continue
        for action in parser._actions:
            for opt in action.option_strings:
                if opt not in ("-h", "--help"):
                    assert f"`{opt}" in doc, f"docs/cli.md: {name} {opt} is not documented"
    for code in EXIT_CODES:
        assert re.search(rf"^\| {code} \|", doc, flags=re.M), f"exit code {code} missing from docs/cli.md"


def test_docs_table_of_known_parameters_is_the_records():
    assert known.markdown_table(registry.models()) in DOC.read_text()


def test_known_parameter_records_are_valid():
    """Each held value names a fitted field of its model, lies in its range and is the default
    (so "held at the start value" and "held at the record's value" agree)."""
    import numpy as np

    from appearance_jax.core.params import ParamSpec, check_value, param_specs

    n = 0
    for m in registry.models():
        specs = param_specs(m.Params)
        for name, (value, why) in known.fit_fixed(m).items():
            assert isinstance(specs.get(name), ParamSpec), f"{m.name}.{name}"
            check_value(f"{m.name}.{name}", value, specs[name])
            np.testing.assert_allclose(np.asarray(getattr(m.Params(), name)), value, err_msg=f"{m.name}.{name}")
            assert why and len(why) < 90
            n += 1
    assert n >= 3


def _console(argv, tmp_path):
    """Run the console entry point in a fresh interpreter (it ends the process), output piped."""
    code = ("import atexit, sys\n"
            "atexit.register(lambda: print('atexit ran'))\n"
            f"sys.argv = ['appearance-jax'] + {list(argv)!r}\n"
            "from appearance_jax.cli import console\n"
            "console()\n"
            "print('not reached')\n")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}  # piped stdout block-buffered
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=tmp_path,
                          env=env)


def test_console_exits_with_the_commands_code_after_flushing_and_atexit(tmp_path):
    # console() leaves by os._exit (no interpreter teardown): piped output must be complete,
    # atexit handlers must have run, and the exit status must be the command's
    ok = _console(["models"], tmp_path)
    assert ok.returncode == 0, ok.stderr
    names = registry.names()
    assert all(n in ok.stdout for n in names)
    assert ok.stdout.rstrip().endswith("atexit ran") and "not reached" not in ok.stdout
    bad = _console(["eval", "--model", "no_such_model"], tmp_path)
    assert bad.returncode == EXIT_USAGE, (bad.returncode, bad.stderr)
    assert "no_such_model" in bad.stderr and "atexit ran" in bad.stdout
