"""Suggestions ("did you mean") for misspelt commands and for every choice of every command's options (one shared mechanism:
``hpe_cli/cli/suggest.py``, applied by the group to every command)."""

from __future__ import annotations

from pathlib import Path

import click
import pytest

from conftest import hpe, hpe_process
from hpe_cli.cli.main import COMMANDS, cli
from hpe_cli.cli.suggest import SuggestChoice, near_names

ROOT = Path(__file__).resolve().parents[2]


def _choice_params():
    out = []
    for name in COMMANDS:
        cmd = cli.get_command(None, name)
        for p in cmd.params:
            if isinstance(p.type, click.Choice):
                out.append((name, p))
    return out


CHOICES = _choice_params()


def test_every_choice_of_every_command_suggests():
    assert len(CHOICES) > 20
    assert all(isinstance(p.type, SuggestChoice) for _, p in CHOICES)


def _typo(choice: str) -> str:
    """A misspelling a user makes: a dash added or removed, a capital, a letter dropped."""
    if "-" in choice:
        return choice.replace("-", "_").upper()
    if len(choice) >= 5:
        return choice[:2] + "-" + choice[2:-1] if choice[-1].isalpha() else choice[:2] + "-" + choice[2:]
    return choice.upper()


@pytest.mark.parametrize("command,param", CHOICES, ids=[f"{c}-{p.name}" for c, p in CHOICES])
def test_choice_typo_names_the_choice(command, param):
    choices = list(param.type.choices)
    for choice in choices:
        typo = _typo(choice)
        if typo in choices:
            continue
        with pytest.raises(click.BadParameter) as e:
            param.type.convert(typo, param, None)
        msg = e.value.format_message()
        assert "did you mean" in msg and repr(choice) in msg.split("did you mean")[1], (typo, msg)


@pytest.mark.parametrize(
    "argv,meant",
    [
        (["export", "x", "-o", "y", "--layout", "fsa-net"], "'fsanet'"),
        (["draw", "x", "-o", "y", "--style", "cub"], "'cube'"),
        (["evaluate", "a", "b", "--protocol", "hopnet"], "'hopenet'"),
        (["audit", "a", "--decoder", "3ddfa-v2"], "'3ddfa_v2'"),
        (["augment", "a", "-o", "b.csv", "--interpolation", "Lanczos"], "'lanczos'"),
    ],
)
def test_choice_typo_through_the_cli(argv, meant):
    r = hpe(*argv)
    assert r.exit_code == 2, r.output
    assert f"(did you mean {meant}?)" in r.output, r.output
    assert len(r.output.strip().splitlines()) == 1


def test_far_choice_gets_no_suggestion():
    r = hpe("draw", "x", "-o", "y", "--style", "zzz")
    assert r.exit_code == 2 and "did you mean" not in r.output and "'axes', 'cube'" in r.output


@pytest.mark.parametrize(
    "typo,meant",
    [("convrt", "convert"), ("relabel_panoptic", "relabel-panoptic"), ("evalute", "evaluate"), ("Audit", "audit")],
)
def test_misspelt_command_suggests(typo, meant):
    p = hpe_process(typo, "x")
    assert p.returncode == 2
    assert p.stderr.strip() == f"Error: No such command {typo!r} (did you mean {meant!r}?).", p.stderr


def test_unrelated_command_gets_no_suggestion():
    r = hpe("frobnicate")
    assert r.exit_code == 2 and "did you mean" not in r.output
    assert "No such command 'frobnicate' (see 'hpe --help' for the commands)." in r.output


@pytest.mark.parametrize(
    "value,names,expected",
    [
        ("fsa-net", ["whenet", "fsanet"], ["fsanet"]),
        ("FSANet", ["whenet", "fsanet"], ["fsanet"]),
        ("whennet", ["whenet", "fsanet"], ["whenet"]),
        ("zzz", ["whenet", "fsanet"], []),
        ("conv", ["convert", "systems"], ["convert"]),
    ],
)
def test_near_names(value, names, expected):
    assert near_names(value, names) == expected
