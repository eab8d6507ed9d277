"""Options fields renamed to the spelling every command shares keep their old keyword, with a DeprecationWarning."""

from __future__ import annotations

import dataclasses
import warnings

import pytest

from hpe_cli.errors import UsageError
from hpe_cli.pipelines.audit import AuditOptions
from hpe_cli.pipelines.augment import AugmentOptions
from hpe_cli.pipelines.draw import DrawOptions

CASES = [
    (lambda **kw: AugmentOptions("hflip", **kw), "workers", "threads", 2, 3),
    (DrawOptions, "rejects_path", "rejects", "old.csv", "new.csv"),
    (AuditOptions, "strict_rejects", "strict", True, None),
    (AuditOptions, "workers", "threads", 2, 3),
]


@pytest.mark.parametrize("make, old, new, value, other", CASES, ids=[c[1] for c in CASES])
def test_old_keyword_works_once_with_a_warning(make, old, new, value, other):
    with pytest.warns(DeprecationWarning, match=f"{old}= is deprecated, use {new}="):
        opts = make(**{old: value})
    assert getattr(opts, new) == value and getattr(opts, old) is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # replace() runs __post_init__ again: no second warning
        assert getattr(dataclasses.replace(opts), new) == value
        assert getattr(make(**{new: value}), new) == value  # the new spelling: no warning
    if other is not None:
        with pytest.warns(DeprecationWarning), pytest.raises(UsageError, match=f"{old}, {new}: expected one"):
            make(**{old: value, new: other})


def test_audit_file_takes_workers_as_threads_with_a_warning(tmp_path):
    """``audit_file(workers=)`` was released as a spelling of ``threads``: it still works, and warns."""
    from hpe_cli.api import audit_file

    src = tmp_path / "labels.csv"
    src.write_text("image,yaw,pitch,roll\na.jpg,10,20,30\nb.jpg,-5,0,5\n")
    with pytest.warns(DeprecationWarning, match="workers= is deprecated, use threads="):
        old = audit_file(src, "300w_lp", workers=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert audit_file(src, "300w_lp", threads=2)["rows"] == old["rows"] == 2
    with pytest.warns(DeprecationWarning), pytest.raises(UsageError, match="workers, threads: expected one"):
        audit_file(src, "300w_lp", workers=2, threads=3)
