"""ST 1201 IMAPB decoding against stanag4609's own encoder (issue 55)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st


@settings(max_examples=60, deadline=None)
@given(st.floats(-900.0, 19000.0), st.integers(2, 4), st.sampled_from([(-900.0, 19000.0), (-19.2, 19.2),
                                                                       (-1e6, 1e6), (0.0, 360.0)]))
def test_55_imapb_decodes_what_stanag4609_encodes(x, length, bounds):
    """ST 1201 IMAPB: eoloc's decoder against stanag4609's own encoder, for ranges that straddle
    zero (where the zero offset matters) and ones that do not: within the format's resolution."""
    from stanag4609.imap import IMAPB

    from eoloc.io.klv import st0903

    lo, hi = bounds
    x = min(max(x, lo), hi)
    codec = IMAPB(lo, hi, length)
    raw = codec.encode(x)
    got = st0903.IMAPB(lo, hi, length)(raw)
    want = codec.decode(raw)
    step = 2.0 ** (np.ceil(np.log2(hi - lo)) - (8 * length - 1))
    assert abs(got - float(want)) <= 1e-9 * max(1.0, abs(float(want))) and abs(got - x) <= step
