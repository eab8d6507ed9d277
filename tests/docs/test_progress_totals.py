"""Progress bars know their total wherever it is known before reading: Parquet row counts from the metadata,
``.mat`` file counts."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from conftest import hpe
from hpe_cli.cli.options import known_rows

ROOT = Path(__file__).resolve().parents[2]
LABELS = ROOT / "sample_data" / "labels_300wlp.csv"
AFLW = ROOT / "sample_data" / "aflw2000"


class Bar:
    """Records the total the bar had at each update."""

    def __init__(self, total=None, **_):
        self.total, self.seen, self.n = total, [], 0

    def update(self, n):
        self.seen.append(self.total)
        self.n += n

    def close(self):
        pass


@pytest.fixture
def bars(monkeypatch):
    made = []

    def factory(total=None, **kw):
        made.append(Bar(total))
        return made[-1]

    from hpe_cli.cli import augment, convert, evaluate

    for mod in (convert, augment, evaluate):
        monkeypatch.setattr(mod, "progress", factory)
    return made


@pytest.fixture
def parquet(tmp_path):
    path = tmp_path / "l.parquet"
    pd.read_csv(LABELS).to_parquet(path)
    return path


def test_known_rows(parquet):
    assert known_rows(parquet) == 204
    assert known_rows(AFLW) == 4
    assert known_rows(parquet, AFLW) == 208
    assert known_rows(LABELS) is None and known_rows(parquet, LABELS) is None


def test_convert_bar_total(bars, parquet, tmp_path):
    r = hpe(
        "convert", parquet, "-o", tmp_path / "o.parquet", "--from", "300w_lp", "--to", "6drepnet", "--batch-size", "50"
    )
    assert r.exit_code == 0, r.output
    assert bars[0].seen and set(bars[0].seen) == {204} and bars[0].n == 204


def test_augment_bar_total(bars, parquet, tmp_path):
    r = hpe(
        "augment", parquet, "-o", tmp_path / "o.parquet", "--image-size", "450x450", "--hflip", "--batch-size", "64"
    )
    assert r.exit_code == 0, r.output
    assert set(bars[0].seen) == {204} and bars[0].n == 204


def test_evaluate_bar_total(bars, parquet, tmp_path):
    r = hpe("evaluate", parquet, parquet, "--pred-system", "300w_lp", "--gt-system", "300w_lp", "--key", "image")
    assert r.exit_code == 0, r.output
    assert set(bars[0].seen) == {408} and bars[0].n == 408


def test_csv_bar_has_no_made_up_total(bars, tmp_path):
    r = hpe("convert", LABELS, "-o", tmp_path / "o.csv", "--from", "300w_lp", "--to", "6drepnet")
    assert r.exit_code == 0 and set(bars[0].seen) == {None}
