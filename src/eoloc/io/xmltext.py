"""Text an XML 1.0 document can hold, for the XML writers (KML, CoT).

XML 1.0 has no way to write most C0 control characters, not even escaped (``&#7;`` is not
well-formed either), nor U+FFFE, U+FFFF or a lone surrogate; a platform designation or a target id
read from a stream or a CSV can hold any of them. The writers pass every value through
:func:`xml_text` and then through their XML serialiser, which escapes ``&``, ``<``, quotes and the
rest.
"""

from __future__ import annotations

import re

NOT_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ufffe\uffff\ud800-\udfff]")  # not a Char of XML 1.0


def xml_text(value) -> str:
    """``value`` as text: the characters XML 1.0 cannot hold (C0 controls but tab, line feed and
    carriage return; U+FFFE, U+FFFF; lone surrogates) replaced by U+FFFD, everything else kept."""
    return NOT_XML.sub("\ufffd", str(value))
