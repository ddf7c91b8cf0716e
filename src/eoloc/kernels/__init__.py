"""The numeric kernels, each written once: the math component-wise (:mod:`.core`), the M4 march
over a DEM (:mod:`.march`) and the orthorectification passes (:mod:`.ortho`); the numba backend
that compiles them (:mod:`.compiled`) and the dispatcher that runs them on arrays (:mod:`.backend`).
Nothing here knows about files, configurations or the command line."""
