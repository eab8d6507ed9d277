"""open_labels: the table, its system and its label storage decided once (checked against the readers)."""

from pathlib import Path

import pytest

from hpe_cli.errors import HpeError, UsageError
from hpe_cli.io.label_source import open_labels
from hpe_cli.registry import Registry

SAMPLES = Path(__file__).resolve().parents[2] / "sample_data"


def test_csv_without_metadata_takes_the_default_then_the_option():
    src = open_labels(SAMPLES / "labels_300wlp.csv")
    assert (src.system.name, src.resolved.origin, src.mode) == ("300w_lp", "default", "angles")
    assert src.where(3) == f"{SAMPLES / 'labels_300wlp.csv'}: line 3"
    src = open_labels(SAMPLES / "labels_300wlp.csv", "scipy_zyx")
    assert (src.system.name, src.resolved.origin) == ("scipy_zyx", "option")


def test_dataset_format_fixes_the_system_and_converts_for_output():
    src = open_labels(SAMPLES / "aflw2000", "6drepnet", option_is_output=True)
    assert src.system.name == "300w_lp" and src.output_system.name == "6drepnet" and src.dataset
    with pytest.raises(UsageError, match="disagrees"):
        open_labels(SAMPLES / "aflw2000", "6drepnet")


def test_mode_and_key_are_checked():
    with pytest.raises(HpeError, match="r00"):
        open_labels(SAMPLES / "labels_300wlp.csv", mode="matrix")
    with pytest.raises(HpeError, match="missing key column"):
        open_labels(SAMPLES / "labels_300wlp.csv", key=("nope",))
    assert open_labels(SAMPLES / "labels_300wlp.csv", key=("image",)).key == ("image",)


def test_registry_decorator_lists_and_refuses():
    reg = Registry("widget")

    @reg.register()
    def alpha():
        return 1

    reg.register("beta", 2)
    assert reg.names() == ("alpha", "beta") and reg.get("beta") == 2 and "alpha" in reg
    with pytest.raises(ValueError, match="expected a widget among alpha, beta, got 'gamma'"):
        reg.get("gamma")
    with pytest.raises(ValueError, match="already registered"):
        reg.register("beta", 3)
    with reg.registered("gamma", 3):
        assert reg.get("gamma") == 3
    assert "gamma" not in reg and reg.get("gamma", None) is None
