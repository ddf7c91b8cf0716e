"""eoloc's optional parts: which extra of ``pip install 'eoloc[...]'`` brings each package that the
core install (the math, the stop rules, DEMs, telemetry, KLV and photo readers, the file outputs)
does without, and the message for a command that reaches one that is missing."""

from __future__ import annotations

from importlib.util import find_spec

from ..errors import MissingExtraError

#: import name -> (package on PyPI, the extras that bring it, what it is for)
EXTRAS: dict[str, tuple[str, tuple[str, ...], str]] = {
    "fastapi": ("fastapi", ("service", "live"), "the HTTP API and the live map's server"),
    "starlette": ("fastapi", ("service", "live"), "the HTTP API and the live map's server"),
    "fastapi_offline": ("fastapi-offline", ("service", "live"), "the API's offline documentation pages"),
    "uvicorn": ("uvicorn", ("service", "live"), "the HTTP server of `eoloc serve` and `eoloc live --map`"),
    "websockets": ("websockets", ("live",), "the live map's WebSocket"),
    "takproto": ("takproto", ("live",), "TAK protocol 1"),
    "cryptography": ("cryptography", ("live",), "TAK client certificates"),
    "dask": ("dask[distributed]", ("batch",), "--dask: Monte Carlo, sweeps and archives on a cluster"),
    "distributed": ("dask[distributed]", ("batch",), "--dask: Monte Carlo, sweeps and archives on a cluster"),
    "av": ("av", ("video",), "video files and network video sources, through FFmpeg"),
    "cv2": ("opencv-python-headless", ("video",), "image work on video frames (OpenCV)"),
    "mercantile": ("mercantile", ("video",), "the mosaic's map tiles"),
    "matplotlib": ("matplotlib", ("report",), "pictures: plots, the report, the map's hillshade"),
    "folium": ("folium", ("report",), "the HTML map"),
    "sklearn": ("scikit-learn", ("report",), "the tree ensemble of `eoloc compensate`'s cross-validation"),
    "onnxruntime": ("onnxruntime", ("onnx",), "running a learned detector (--detect MODEL.onnx)"),
}


def installed(module: str) -> bool:
    """Whether ``module`` (an import name) can be imported."""
    try:
        return find_spec(module) is not None
    except ImportError:  # (a finder that refuses it)
        return False


def missing_extra(exc: ModuleNotFoundError) -> MissingExtraError | None:
    """The message for an import of one of eoloc's optional packages that failed, or None when the
    missing module is not one of them (a broken install, a bug: its traceback stays)."""
    root = (exc.name or "").split(".")[0]
    if root not in EXTRAS:
        return None
    package, extras, what = EXTRAS[root]
    how = " or ".join(f"pip install 'eoloc[{e}]'" for e in extras)
    return MissingExtraError(f"this needs {package} ({what}), an optional part of eoloc that is not installed: {how} "
                        "(or 'eoloc[all]' for every optional part)")


def require(module: str) -> None:
    """Raise :class:`MissingExtraError` when optional ``module`` is not installed."""
    if not installed(module):
        raise missing_extra(ModuleNotFoundError(f"No module named {module!r}", name=module))
