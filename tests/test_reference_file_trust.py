"""The stored reference's restricted unpickler (quadsim.gap.reffile._Restricted): what a
stage may name, and what it may not even where the name is a quadsim or numpy class."""

from __future__ import annotations

import io
import pickle

import numpy as np
import pytest

from quadsim.gap.reffile import _Restricted, read_reference, shipped_reference


def _load(obj):
    return _Restricted(io.BytesIO(pickle.dumps(obj, protocol=4))).load()


class _Memmap:
    """A pickle that, unpickled unrestricted, would create (truncate) a file through
    ``numpy.memmap``'s constructor."""

    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return (np.memmap, (self.path, np.uint8, "w+", 0, (16,)))


class _Dataclass:
    """A pickle naming a quadsim dataclass: allowed (its constructor only sets fields)."""

    def __reduce__(self):
        from quadsim.gap.cache import ReferenceStore

        return (ReferenceStore, ("/tmp/never",))


def test_numpy_arrays_scalars_and_dtypes_read_back():
    value = {"a": np.arange(5.0), "i": np.int64(3), "f": np.float32(2.5),
             "d": np.dtype("f8"), "b": np.array([True, False])}
    back = _load(value)
    assert back["a"].tobytes() == value["a"].tobytes() and back["i"] == 3
    assert back["f"].dtype == np.float32 and back["d"] == np.dtype("f8")
    assert back["b"].tolist() == [True, False]


def test_memmap_refused_and_no_file_made(tmp_path):
    target = tmp_path / "made"
    with pytest.raises(pickle.UnpicklingError, match="memmap"):
        _load(_Memmap(target))
    assert not target.exists()


def test_only_dataclasses_of_quadsim():
    from quadsim.gap.cache import ReferenceStore
    from quadsim.gap.reffile import Stored

    assert isinstance(_load(_Dataclass()), ReferenceStore)      # fields only, nothing opened

    class _Cls:
        def __reduce__(self):
            from quadsim.core.errors import InputError  # a class, not a dataclass

            return (InputError, ("x",))

    with pytest.raises(pickle.UnpicklingError, match="quadsim.core.errors.InputError"):
        _load(_Cls())
    assert Stored.__dataclass_fields__      # the module's own types are dataclasses


def test_the_shipped_reference_reads_under_the_restriction():
    path = shipped_reference("crazyflie21")
    assert path is not None
    stored = read_reference(path)
    assert stored.stage.count == 20 and stored.header["count"] == 20


def test_a_judged_flight_that_is_one_of_the_references_is_said(tmp_path):
    """own_flights / in_sample_note: a judged log with the bytes of one of the stored
    reference's flights is named (judged in sample); a copy with other bytes, or none, not."""
    import hashlib

    from quadsim.gap.reffile import in_sample_note, own_flights

    ref = tmp_path / "ref.csv.gz"
    ref.write_bytes(b"t,x\n0,1\n")
    same = tmp_path / "renamed.csv.gz"
    same.write_bytes(ref.read_bytes())
    other = tmp_path / "other.csv.gz"
    other.write_bytes(b"t,x\n0,2\n")
    header = {"count": 2, "references": [
        {"file": "nominal/ref.csv.gz", "bytes": 8,
         "sha256": hashlib.sha256(ref.read_bytes()).hexdigest()},
        {"file": "nominal/b.csv.gz", "bytes": 1, "sha256": "0" * 64}]}
    assert own_flights(header, [same, other, tmp_path / "missing"]) == [
        (str(same), "nominal/ref.csv.gz")]
    note = in_sample_note(header, [same, other])
    assert note.startswith(f"judged in sample: {same} (its nominal/ref.csv.gz) is among the "
                           "stored reference's own 2 flights (the same bytes)")
    assert in_sample_note(header, [other]) is None
