"""Every ``hpe`` example in the docs runs in CI.

Marked examples (``<!-- hpe-example -->`` before a ``bash`` block) run on the shipped samples and must exit 0
and print what the page shows under ``<!-- hpe-output -->`` (refresh with
``python tests/docs/doc_examples.py --update``). Every other ``hpe`` command line in a code block of the docs or
the README is parsed by the real command (options, choices and value types are checked; only paths that do not
exist on this machine are allowed to fail), so no page shows an option that does not exist.
"""

from __future__ import annotations

import re
import shlex
import sys
from pathlib import Path

import click
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
import doc_examples as dx  # noqa: E402

PAGES = dx.pages()


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(dx.DOCS)) for p in PAGES])
def test_marked_examples_run_and_print_what_the_page_shows(page):
    for ex, out, codes in dx.run_page(page):
        for cmd, code in codes:
            assert code == 0, f"{page.name}: {cmd!r} exited {code}:\n{out}"
        if ex.output is not None:
            assert dx.comparable(out) == dx.comparable(ex.output), (
                f"{page.name}: the output shown under {ex.commands[0]!r} is stale; "
                "run python tests/docs/doc_examples.py --update"
            )


def test_no_page_shows_a_number_at_rounding_level():
    """Digits below 1e-9 differ between CPUs (SIMD paths): pages print them as a bound (``< 1e-12``)."""
    bad = []
    for page in PAGES:
        for ex in dx.examples(page):
            if ex.output is not None and dx.rounding_level_numbers(ex.output):
                bad.append(f"{page.name}: {dx.rounding_level_numbers(ex.output)} under {ex.commands[0]!r}")
    assert not bad, "\n".join(bad)


def test_comparable_ignores_rounding_level_digits_only():
    assert dx.comparable("error: 1.12e-15; 2.5e-3") == dx.comparable("error: 6.57e-16; 2.5e-3")
    assert dx.comparable("error: 2.5e-3") != dx.comparable("error: 2.6e-3")


SIMD_PAGES = ["commands/convert.md", "getting-started.md"]


@pytest.mark.parametrize("name", SIMD_PAGES)
def test_round_trip_examples_with_numpy_simd_paths_restricted(name, monkeypatch):
    """The pages whose outputs carry round-trip errors print the same with numpy's SIMD dispatch turned off
    (``NPY_DISABLE_CPU_FEATURES``): another CPU's code paths, on this machine."""
    env = dx.simd_restricted_env()
    if not env["NPY_DISABLE_CPU_FEATURES"]:
        pytest.skip("numpy dispatches to no SIMD extension above its baseline on this CPU")
    monkeypatch.setenv("NPY_DISABLE_CPU_FEATURES", env["NPY_DISABLE_CPU_FEATURES"])
    probe = "from numpy._core._multiarray_umath import __cpu_features__ as f; import sys; sys.argv.pop(0); "
    probe += "print(sum(f[n] for n in sys.argv))"
    import subprocess

    on = subprocess.run(
        [sys.executable, "-c", probe, *env["NPY_DISABLE_CPU_FEATURES"].split()],
        env=env,
        text=True,
        capture_output=True,
        check=True,
    ).stdout.strip()
    assert on == "0", "numpy in a child process ignored NPY_DISABLE_CPU_FEATURES"
    page = dx.DOCS / name
    for ex, out, codes in dx.run_page(page):
        for cmd, code in codes:
            assert code == 0, f"{name}: {cmd!r} exited {code} with NPY_DISABLE_CPU_FEATURES set:\n{out}"
        if ex.output is not None:
            assert dx.normalise(out) == dx.normalise(ex.output), f"{name}: {ex.commands[0]!r} prints differently"


def _fenced(text):
    """(language, body) of every fenced code block, fences paired in order."""
    out, lang, body = [], None, []
    for line in text.splitlines():
        if line.lstrip().startswith("```"):
            if lang is None:
                lang, body = line.strip()[3:].split(" ")[0], []
            else:
                out.append((lang, "\n".join(body) + "\n"))
                lang = None
        elif lang is not None:
            body.append(line)
    return out


def _all_command_lines():
    files = sorted(dx.DOCS.rglob("*.md")) + [dx.ROOT / "README.md"]
    out = []
    for f in files:
        text = f.read_text(encoding="utf-8")
        blocks = [body for lang, body in _fenced(text) if lang in ("", "bash", "sh", "console", "shell")]
        blocks += re.findall(r"((?:^    hpe .*\n)+)", text, re.M)  # indented blocks
        for block in blocks:
            for line in dx.commands(block.replace("$ hpe ", "hpe ")):
                out.append((f.relative_to(dx.ROOT), line))
    from hpe_cli.cli.main import COMMANDS, cli

    for name in COMMANDS:  # the examples of every --help too
        helptext = (cli.get_command(None, name).help or "").replace("\\\n", "\\\n")
        for line in dx.commands(helptext):
            out.append((f"hpe {name} --help", line))
    return out


def test_every_command_line_in_the_docs_parses():
    from hpe_cli.cli.main import cli

    seen, bad = 0, []
    for where, line in _all_command_lines():
        line = re.sub(r"\s[12]?>\s*\S+|\|.*$|\$\{?\w+\}?", lambda m: " X" if m.group(0).startswith("$") else "", line)
        if re.search(r"--canvas|--units|--image-size \d+ \d+", line):
            bad.append(f"{where}: {line}: a deprecated spelling")
        try:
            argv = shlex.split(line)[1:]
        except ValueError as exc:
            bad.append(f"{where}: {line}: {exc}")
            continue
        if not argv or argv[0] in ("-h", "--help"):
            continue
        cmd = cli.get_command(None, argv[0])
        if cmd is None:
            bad.append(f"{where}: {line}: no command {argv[0]!r}")
            continue
        seen += 1
        try:
            with click.Context(cli, info_name="hpe") as parent:
                cmd.make_context(argv[0], argv[1:], parent=parent)
        except click.BadParameter as exc:
            if not re.search("does not exist|no such system file", exc.format_message()):
                bad.append(f"{where}: {line}: {exc.format_message()}")
        except click.UsageError as exc:
            bad.append(f"{where}: {line}: {exc.format_message()}")
    assert seen > 50
    assert not bad, "\n".join(bad)
