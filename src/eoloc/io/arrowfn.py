"""The few pyarrow compute functions the CSV reader and writer use, called by name.

``import pyarrow.compute`` builds a Python wrapper, docstring included, for each of pyarrow's
~400 compute functions: 25-28 ms with the GIL held, paid by every command that reads or writes a
CSV (`eoloc locate` of 10^6 detections spends ~0.3 s of its ~0.9 s importing). The functions
here call pyarrow's ``call_function`` by name with the same options as those wrappers (tested
against them), so the CSV path never imports ``pyarrow.compute``. pyarrow's own methods that
route through it (``Array.cast``, ``fill_null``, ``is_null``, ``dictionary_encode``) are
replaced here too.
"""

from __future__ import annotations

try:  # where pyarrow.compute takes them from (pyarrow >= 1.0)
    import pyarrow._compute as _fn
except ImportError:  # pragma: no cover - a pyarrow that moved them: the public module has them all
    import pyarrow.compute as _fn

call_function = _fn.call_function


def fill_null(values, fill):
    """``values`` with each null replaced by ``fill`` (a Python value of their type)."""
    import pyarrow as pa

    return call_function("coalesce", [values, pa.scalar(fill, type=values.type)])


def cast(values, target_type):
    """``values`` as ``target_type`` (safe: an invalid value raises ``pa.ArrowInvalid``)."""
    return call_function("cast", [values], _fn.CastOptions.safe(target_type))


def is_null(values):
    return call_function("is_null", [values], _fn.NullOptions())


def dictionary_encode(values):
    """``values`` as a dictionary array: indices into its distinct values (nulls stay null)."""
    return call_function("dictionary_encode", [values], _fn.DictionaryEncodeOptions())


def utf8_trim_whitespace(values):
    return call_function("utf8_trim_whitespace", [values])


def take(values, indices):
    """``values[indices]`` (indices checked)."""
    return call_function("take", [values, indices], _fn.TakeOptions(boundscheck=True))


def join_cells(*cells_and_separator, null_replacement: str | None = None):
    """Element-wise concatenation of string arrays (or scalars), the last argument the separator;
    a null cell makes the result null, or is ``null_replacement`` when that is given."""
    options = _fn.JoinOptions() if null_replacement is None else _fn.JoinOptions("replace", null_replacement)
    return call_function("binary_join_element_wise", list(cells_and_separator), options)


def matches(values, pattern: str):
    """Whether each string matches the regular expression ``pattern`` anywhere."""
    return call_function("match_substring_regex", [values], _fn.MatchSubstringOptions(pattern))


def replace_all(values, pattern: str, replacement: str):
    """Each string with every ``pattern`` (plain text) replaced by ``replacement``."""
    return call_function("replace_substring", [values], _fn.ReplaceSubstringOptions(pattern, replacement))


def replace_regex(values, pattern: str, replacement: str):
    """Each string with every match of the regular expression ``pattern`` replaced by
    ``replacement`` (RE2 syntax; ``\\1`` is the first group)."""
    return call_function("replace_substring_regex", [values], _fn.ReplaceSubstringOptions(pattern, replacement))


def equal(a, b):
    return call_function("equal", [a, b])


def or_(a, b):
    return call_function("or", [a, b])


def and_not(a, b):
    return call_function("and_not", [a, b])


def if_else(condition, a, b):
    return call_function("if_else", [condition, a, b])


def any_true(values) -> bool:
    """Whether any element is true (nulls skipped)."""
    return bool(call_function("any", [values], _fn.ScalarAggregateOptions()).as_py())
