"""The compiled CSV row renderer (eoloc.io.csvrows) against its references: every number against
orjson's text of numpy's rounding, and whole files byte for byte against the writer's pure-Python
path (orjson + pyarrow's join), for every column kind in any order."""

from __future__ import annotations

import numpy as np
import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eoloc.io import csvfile, rows
from eoloc.io.records import Coded, Records


def test_the_row_renderer_is_built():
    """`make test` installs the package with its C extension: the tests below compare it with the
    pure-Python path, so a missing build must fail here, not pass by comparing that path with itself."""
    from eoloc.io import csvrows

    assert rows.compiled() is csvrows


def _orjson_cells(v: np.ndarray, decimals: int) -> list[str]:
    return orjson.dumps(np.round(v, decimals), option=orjson.OPT_SERIALIZE_NUMPY).decode()[1:-1].split(",")


_magnitudes = st.sampled_from([1e-12, 1e-9, 3e-7, 1e-6, 1e-5, 1e-3, 0.5, 1.0, 7.0, 1e3, 1e6, 1e9, 9e10])


@settings(max_examples=150, deadline=None)
@given(data=st.data(), decimals=st.sampled_from([0, 1, 4, 9]), magnitude=_magnitudes)
def test_numbers_are_orjsons_text_of_numpys_rounding(data, decimals, magnitude):
    """Each finite number whose rounded value has at most 15 digits: the same text as orjson gives
    for np.round(x, decimals) (shortest round trip, "1.0" for whole values, exponent below 1e-5,
    "-0.0"); NaN: the empty cell."""
    from eoloc.io import csvrows

    limit = 10.0 ** (15 - decimals)
    xs = data.draw(st.lists(st.floats(-1.0, 1.0, allow_nan=False), min_size=1, max_size=60))
    v = np.array(xs) * magnitude
    v = np.concatenate([v[np.abs(v) < limit], [0.0, -0.0, 0.5, -2.5, 1e-5, -9.9e-6]])
    out = csvrows.render(0, len(v), ((1, v, decimals, False, b"", b",", b","),)).decode().split(",")[:-1]
    assert out == _orjson_cells(v, decimals)
    gaps = v.copy()
    gaps[::3] = np.nan
    out = csvrows.render(0, len(v), ((1, gaps, decimals, False, b"", b"\n", b"\n"),)).decode().split("\n")[:-1]
    want = _orjson_cells(np.nan_to_num(gaps), decimals)
    assert out == ["" if np.isnan(g) else w for g, w in zip(gaps, want, strict=True)]


@settings(max_examples=60, deadline=None)
@given(ints=st.lists(st.integers(-2**63, 2**63 - 1), min_size=1, max_size=40), start=st.integers(0, 5))
def test_ints_and_rows_from_an_offset(ints, start):
    """int64 cells as str(); rows start .. start+n of the arrays."""
    from eoloc.io import csvrows

    v = np.array([0] * start + ints, dtype=np.int64)
    out = csvrows.render(start, len(ints), ((2, v, b"", b"\n"),)).decode()
    assert out == "".join(f"{i}\n" for i in ints)


def test_bad_input_is_an_error_not_a_crash():
    """A code past its names, a row past a column's end, a wrong spec: a Python exception."""
    from eoloc.io import csvrows

    offsets, names = np.array([0, 2, 4], dtype=np.int32), b"a,b,"
    assert csvrows.render(0, 3, ((3, np.array([1, 0, 1], dtype=np.int8), offsets, names),)) == b"b,a,b,"
    with pytest.raises(ValueError, match="code past its names"):
        csvrows.render(0, 2, ((3, np.array([0, 2], dtype=np.int32), offsets, names),))
    with pytest.raises(IndexError):
        csvrows.render(1, 3, ((2, np.arange(3), b"", b","),))
    with pytest.raises(TypeError):
        csvrows.render(0, 1, ((1, np.arange(1, dtype=np.float32), 4, False, b"", b",", b","),))
    with pytest.raises(ValueError, match="15 digits"):
        csvrows.render(0, 1, ((1, np.array([1e12]), 4, False, b"", b",", b","),))
    with pytest.raises(ValueError):
        csvrows.render(0, 1, ((7, b"x"),))


def test_negative_zero_is_written_as_orjson_writes_it(tmp_path):
    """-0.0 is "-0.0" in both paths, also in a chunk whose numbers are otherwise all 0.0 (the
    pyarrow path wrote such a chunk as one value, "0.0" throughout; hypothesis found it)."""
    v = np.array([0.0, 51.5, 0.0, 0.0, -0.0, 0.0])
    old = csvfile.CSV_CHUNK
    csvfile.CSV_CHUNK = 3
    try:
        fast = csvfile.write_csv(tmp_path / "fast.csv", Records({"x_m": v})).read_text()
        rows.USE_COMPILED = False
        slow = csvfile.write_csv(tmp_path / "slow.csv", Records({"x_m": v})).read_text()
    finally:
        csvfile.CSV_CHUNK, rows.USE_COMPILED = old, True
    assert fast == slow == "x_m\n0.0\n51.5\n0.0\n0.0\n-0.0\n0.0\n"


_text = st.text(alphabet=st.sampled_from(list('ab ,"\n\r;é')), max_size=6)
_KINDS = ["int", "int32", "uint64", "int_strided", "float", "float_strided", "tiny", "huge", "inf", "float32", "whole",
          "same", "none", "text", "bool", "coded", "coded_u8"]


@settings(max_examples=120, deadline=None)
@given(data=st.data(), n=st.integers(1, 14), width=st.integers(1, 6), chunk=st.sampled_from([3, 5, 1 << 15]))
def test_compiled_and_pyarrow_paths_write_the_same_bytes(tmp_path_factory, data, n, width, chunk):
    """Any order of column kinds (those csvrows writes itself and those it takes pre-rendered:
    infinities, numbers past 15 digits, float32, text), the last and a lone column included,
    in several chunks: the compiled renderer writes the very bytes of the pyarrow path."""
    kinds = data.draw(st.lists(st.sampled_from(_KINDS), min_size=width, max_size=width))
    cols, coded = {}, {}
    floats = st.floats(-1e6, 1e6) | st.just(float("nan"))
    for i, kind in enumerate(kinds):
        name = f"c{i}_deg" if i % 2 else f"c{i}"
        if kind in ("int", "int32", "uint64", "int_strided"):
            lo, hi, dtype = {"int": (-2**63, 2**63 - 1, np.int64), "int32": (-2**31, 2**31 - 1, np.int32),
                             "uint64": (0, 2**64 - 1, np.uint64), "int_strided": (-9, 9, np.int64)}[kind]
            v = np.array(data.draw(st.lists(st.integers(lo, hi), min_size=n, max_size=n)), dtype=dtype)
            v = np.repeat(v, 2)[::2] if kind == "int_strided" else v  # a view with a stride
        elif kind in ("float", "float_strided", "tiny", "huge", "inf", "float32", "whole", "same", "none"):
            xs = np.array(data.draw(st.lists(floats, min_size=n, max_size=n)))
            v = {"float": xs, "float_strided": np.repeat(xs, 2)[::2], "tiny": xs * 1e-11, "huge": xs * 1e12,
                 "inf": np.where(xs > 0, np.inf, xs),
                 "float32": xs.astype(np.float32), "whole": np.round(xs), "same": np.full(n, -2.5),
                 "none": np.full(n, np.nan)}[kind]
        elif kind == "bool":
            v = np.array(data.draw(st.lists(st.booleans(), min_size=n, max_size=n)))
        else:
            texts = data.draw(st.lists(st.none() | _text, min_size=n, max_size=n))
            v = np.array(texts, dtype=object)
            if kind.startswith("coded"):
                table, codes = np.unique(np.array(["" if t is None else t for t in texts]), return_inverse=True)
                codes = codes.astype(np.uint8 if kind == "coded_u8" else np.int32)
                coded[name] = Coded(codes, table.astype(object))
                v = table.astype(object)[codes]
        cols[name] = v
    tmp = tmp_path_factory.mktemp("same")
    old = csvfile.CSV_CHUNK
    csvfile.CSV_CHUNK = chunk
    try:
        fast = csvfile.write_csv(tmp / "fast.csv", Records(cols, coded)).read_bytes()
        rows.USE_COMPILED = False
        slow = csvfile.write_csv(tmp / "slow.csv", Records(cols, coded)).read_bytes()
    finally:
        csvfile.CSV_CHUNK, rows.USE_COMPILED = old, True
    assert fast == slow
