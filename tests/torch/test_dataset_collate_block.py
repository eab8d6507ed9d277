"""HeadPoseDataset batches: one storage per batch, values equal to torch's default_collate key by key."""

import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchvision")

from torch.utils.data import DataLoader, default_collate
from torchvision.transforms import v2

from conftest import REALDATA
from hpe_cli.torch import HeadPoseDataset
from hpe_cli.torch import transforms as T
from hpe_cli.torch.collate import Sample, collate_samples

AFLW = REALDATA / "aflw2000_prnet"
pytestmark = pytest.mark.skipif(not AFLW.is_dir(), reason="realdata not available")


def _same(a, b):
    a, b = a.as_subclass(torch.Tensor), b.as_subclass(torch.Tensor)
    if a.is_floating_point():  # NaN = a missing landmark
        return torch.equal(a.isnan(), b.isnan()) and torch.equal(a.nan_to_num(), b.nan_to_num())
    return torch.equal(a, b)


def _equal(got, ref):
    assert list(got) == list(ref)
    for k, v in ref.items():
        assert type(got[k]) is type(v), k
        assert got[k].dtype == v.dtype and got[k].shape == v.shape and got[k].is_contiguous(), k
        assert _same(got[k], v), k


def test_collate_block_equals_default_collate_in_one_storage():
    ds = HeadPoseDataset(AFLW, crop=0.25, size=64, hflip=0.5)
    batch = ds.__getitems__([0, 5, 3, 9])
    assert all(type(s) is Sample for s in batch)
    got = collate_samples(batch)
    _equal(got, default_collate([dict(s) for s in batch]))
    assert len({v.untyped_storage().data_ptr() for v in got.values()}) == 1
    assert DataLoader(ds, batch_size=4).collate_fn([ds[1], ds[2]]).keys() == got.keys()  # registered


def test_collate_block_through_workers_and_with_a_transform():
    torch.manual_seed(0)
    ds = HeadPoseDataset(AFLW, crop=0.25, size=64, hflip=1.0)
    ref = [default_collate([dict(ds[i]) for i in range(k, k + 4)]) for k in (0, 4)]
    for workers in (0, 2):
        for got, want in zip(DataLoader(ds, batch_size=4, num_workers=workers), ref):
            _equal(got, want)
    tv = HeadPoseDataset(AFLW, crop=0.25, size=64, transform=v2.Compose([T.RandomHorizontalFlip(p=1.0)]))
    got = next(iter(DataLoader(tv, batch_size=3, num_workers=1)))
    want = default_collate([dict(tv[i]) for i in range(3)])
    assert list(got) == list(want)
    for k in want:
        assert _same(got[k], want[k]), k
        assert type(got[k]) is type(want[k]), k


def test_collate_block_odd_batches_behave_as_default_collate():
    big = [
        Sample(image=torch.zeros(3, 64, 64, dtype=torch.uint8), index=0),
        Sample(image=torch.zeros(3, 1, 64, dtype=torch.uint8), index=1),
    ]  # numpy would broadcast: must not
    with pytest.raises(RuntimeError):
        default_collate([dict(s) for s in big])
    with pytest.raises(RuntimeError):
        collate_samples(big)
    bf = [Sample(x=torch.full((3, 40, 40), k, dtype=torch.bfloat16), s="a") for k in range(3)]  # numpy lacks bf16
    got, want = collate_samples(bf), default_collate([dict(s) for s in bf])
    assert got["s"] == want["s"] and got["x"].dtype == torch.bfloat16 and torch.equal(got["x"], want["x"])
