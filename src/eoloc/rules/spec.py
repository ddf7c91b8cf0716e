"""How users name a stop rule: one :class:`RuleSpec` per rule, all in :data:`SPECS`.

Every front end reads the specs and nothing else: the command line (``--range [R]``,
``--target-height H``, ``--dem FILE``), config files (``[accuracy.stop]``), the HTTP API (the
``stop`` object), ``eoloc batch`` and ``eoloc compensate``. A rule is named by one key everywhere,
its value in the same units: ``range_m``, ``target_height_m``, ``dem``. Python code passes rule
objects (``AtRange(1500.0)``); :func:`rule_from_values` is the adapter for keyed values.

A new rule whose value is a length, a height or a DEM is its file in this package, its kernel,
and its row in :data:`SPECS`: every front end then offers it. The table names the rule's class
by its module, so that reading it (the command line does, at start-up) loads no rule.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from importlib import import_module
from typing import TYPE_CHECKING, Any, Literal

from ..errors import InputError

if TYPE_CHECKING:
    from .base import StopRule

Value = Literal["distance", "height", "dem"]
FROM_RECORDS = "from records"  # a rule's value that asks for each target's own, from its row (RuleSpec.records)


@dataclass(frozen=True)
class RuleSpec:
    """A stop rule as users name it.

    ``key``: the value's name in config files, the HTTP API and keyed Python values (``range_m``);
    ``flag``: the command-line option (``--range``); ``method``: the SPEC method (``M1``);
    ``value``: what the value is — ``"distance"`` (metres > ``minimum``), ``"height"`` (an
    ellipsoidal height in metres within [``minimum``, ``maximum``]) or ``"dem"`` (DEM files on the
    command line and in configs, a served DEM's name in the API); ``help``: the value in words,
    with its unit; ``build``: the rule's class as ``"module:Class"`` of this package (called with
    the value; named, not imported, so that reading the table loads no rule); ``records``: the
    class, named likewise, of the rule that takes each target's own value from its input row (the
    flag given without a value), if the rule has one; ``ground``: the rule stops rays on a surface
    (footprints, ground grids and orthorectification can stand on it).
    """

    key: str
    flag: str
    method: str
    value: Value
    help: str
    build: str
    metavar: str = "M"
    minimum: float = float("-inf")
    maximum: float = float("inf")
    records: str | None = None
    records_help: str = ""
    ground: bool = False

    def rule(self, value: Any) -> StopRule:
        """The rule with ``value`` (not checked: see :func:`rule_from_values`)."""
        return _class(self.build)(value)

    def records_rule(self) -> StopRule:
        """The rule that takes each target's value from its row (``records``)."""
        if self.records is None:
            raise InputError(f"{self.flag} needs a value: {self.help}")
        return _class(self.records)()

    def check(self, x: float) -> str | None:
        """Why the number ``x`` is not a value of this rule (None when it is one)."""
        if self.value == "dem":
            return None
        if not (x == x and abs(x) != float("inf")):
            return f"{self.key} must be a finite number of metres, got {x!r}"
        low_open = self.value == "distance"
        if x < self.minimum or (low_open and x == self.minimum) or x > self.maximum:
            low = f"> {self.minimum:g}" if low_open else f">= {self.minimum:g}"
            return f"{self.key} ({self.help}) must be {low} and <= {self.maximum:g} m, got {x:g}"
        return None


def chosen(values: Mapping[str, Any], specs: Iterable[RuleSpec] | None = None) -> tuple[RuleSpec, Any]:
    """The one rule of ``specs`` (default :data:`SPECS`) that ``values`` (key -> value or None)
    gives a value for; InputError naming every key for none or several, and for an unknown key."""
    specs = SPECS if specs is None else tuple(specs)
    keys = {s.key for s in specs}
    unknown = sorted(set(values) - keys)
    if unknown:
        raise InputError(f"no stop rule is named {', '.join(map(repr, unknown))}; the rules: "
                         f"{', '.join(s.key for s in specs)}")
    given = [(s, values[s.key]) for s in specs if values.get(s.key) is not None]
    if len(given) != 1:
        raise InputError("choose one stop rule: " + ", ".join(f"{s.key} ({s.help})" for s in specs))
    return given[0]


def rule_from_values(values: Mapping[str, Any], specs: Iterable[RuleSpec] | None = None) -> StopRule:
    """The rule of the one key of ``values`` that is not None (see :func:`chosen`), built from its
    value (:data:`FROM_RECORDS`: the rule that takes each target's own from its row); a number
    outside the rule's domain is refused (InputError naming the key)."""
    spec, value = chosen(values, specs)
    if isinstance(value, str) and value == FROM_RECORDS:
        return spec.records_rule()
    if spec.value != "dem" and not hasattr(value, "__len__"):
        why = spec.check(float(value))
        if why is not None:
            raise InputError(why)
    return spec.rule(value)


def rule_from_table(table: Any, dem: Callable[[Any], Any]) -> StopRule:
    """The rule of a stop table — an object with one attribute per key of :data:`SPECS` (a
    config's ``[accuracy.stop]``, the HTTP API's ``stop``) — its DEM value turned into a DEM by
    ``dem`` (a config's files opened, a served DEM looked up by name)."""
    values = {s.key: getattr(table, s.key) for s in SPECS}
    for s in SPECS:
        if s.value == "dem" and values[s.key] is not None:
            values[s.key] = dem(values[s.key])
    return rule_from_values(values)


def _class(where: str) -> type:
    module, name = where.split(":")
    return getattr(import_module(f".{module}", __package__), name)


SPECS: tuple[RuleSpec, ...] = (
    RuleSpec(key="range_m", flag="--range", method="M1", value="distance", metavar="R", minimum=0.0, maximum=1e7,
             help="the laser slant range along every ray, metres", build="at_range:AtRange",
             records="at_range:RangeFromRecords", records_help="each target's range_m column from the files"),
    RuleSpec(key="target_height_m", flag="--target-height", method="M3", value="height", metavar="H",
             minimum=-12_000.0, maximum=1e7, help="the targets' ellipsoidal height, metres", build="at_height:AtHeight",
             ground=True),
    RuleSpec(key="dem", flag="--dem", method="M4", value="dem", metavar="FILE",
             help="the terrain, a DEM", build="on_dem:OnDEM", ground=True),
)
"""The rules users choose by name (command line, config files, HTTP API, batch, compensation):
a new rule's row goes here."""
