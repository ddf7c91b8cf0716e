"""A CoT event (eoloc.io.cot) for any fix row, valid against MITRE's CoT Event 2.0 schema
(issue 49; the io package's own test for issue 55)."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st
from misbcheck import cot_schema

_COT_SCHEMA = None


@settings(max_examples=300, deadline=None)
@given(lat=st.floats(-90, 90), lon=st.floats(-180, 180), h=st.floats(-1e5, 1e5),
       errors=st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(0, 1e12)), min_size=5,
                       max_size=5),
       tid=st.one_of(st.integers(), st.text(max_size=40)))
def test_49_cot_a_fix_with_any_values_makes_a_valid_event(lat, lon, h, errors, tid):
    """Whatever a fix row holds (an uncertainty NaN, infinite, negative or past 10^7 m; a target
    name with markup, control characters or other scripts), its CoT event is valid against the
    CoT schema: ce/le decimals within the schema (9999999, CoT's 'unknown', for what is not a
    usable error), the name escaped."""
    global _COT_SCHEMA
    from eoloc.io.cot import UNKNOWN, cot_event_bytes

    _COT_SCHEMA = _COT_SCHEMA or cot_schema()
    row = {"status": "OK", "lat_deg": lat, "lon_deg": lon, "h_m": h, "target_id": tid,
           **dict(zip(("ce90_m", "le90_m", "sigma_e_m", "sigma_n_m", "sigma_u_m"), errors, strict=True))}
    event = cot_event_bytes(row).decode()
    problems = [str(e)[:200] for e in _COT_SCHEMA.iter_errors(event)]
    assert not problems, (event, problems)
    point = _COT_SCHEMA.to_dict(event)["point"]
    assert all(0 <= float(point[f"@{k}"]) <= UNKNOWN for k in ("ce", "le"))
