"""The protocol table of docs/commands/evaluate.md is the code's: every protocol with its system, formula, filter
and repo@commit source, so the page cannot fall behind a protocol that follows a newer peer commit."""

from pathlib import Path

from hpe_cli.metrics.protocols import PROTOCOLS

PAGE = Path(__file__).resolve().parents[2] / "docs" / "commands" / "evaluate.md"


def test_every_protocol_row_is_on_the_page():
    text = PAGE.read_text()
    esc = lambda t: t.replace("|", "\\|")  # noqa: E731
    for name, p in PROTOCOLS.items():
        row = f"| `{name}` | {esc(p.system)} | {esc(p.formula)} | {esc(p.filter)} | {esc(p.source)} |"
        assert row in text, f"docs/commands/evaluate.md: protocol {name!r} row missing or stale; expected {row}"
