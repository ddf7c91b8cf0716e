"""The job layer: what each `eoloc` command does, as functions that take parsed options and
return typed results. Jobs read their inputs through :mod:`eoloc.io`, never print and never exit;
the CLI and the demo render what they return and write it through :mod:`eoloc.io.writers` (a job
with products of its own has a ``write_*`` function beside it that does only that). A user's mistake is an
:class:`eoloc.errors.EolocError` naming the file, key or option and the fix; a per-target problem is
a status. Layers: core math -> rules -> pipeline/accuracy/sequence -> io -> jobs -> render -> cli."""
