"""The job layer: what each `eoloc` command does, as functions that take parsed options and
return typed results. Jobs read their inputs through :mod:`eoloc.io`, never print and never exit;
the CLI renders what they return and writes it through :mod:`eoloc.io.writers` (a job with
products of its own has a ``write_*`` function beside it that does only that). A user's mistake is
an :class:`eoloc.errors.EolocError` naming the file, key or option and the fix; a per-target
problem is a status. Beside one module per command: :mod:`.tables` (telemetry + detections + stop
rule -> rows, shared by the commands, the service and batch) and :mod:`.klvframes` (ST 0601 +
ST 0903 tables -> frame checks, footprints and fixes). The layers are drawn once, in the README's
"Architecture"."""
