"""Targets from a learned detector the user gives: an ONNX model file run by onnxruntime on the
frames (on the CPU; nothing is downloaded).

The model's first input is an image batch (1, 3, H, W), RGB scaled to 0..1; a fixed H, W is taken
from the model, a free one is 640. Each frame is letterboxed into it (scaled to fit, the rest
grey 114, as YOLO is trained). Its first output is read as YOLO detections: (1, 4 + C, N) as
YOLOv8/v11 write them (box centre x, y, width, height in input pixels, then C class scores), or
(1, N, 5 + C) as YOLOv5/v7 (box, objectness, class scores; a detection's score is objectness x
class score). Class names come from the model's metadata (``names``, as Ultralytics exports it),
else class_0, class_1, ...; ``classes`` keeps only those named. Boxes scoring at least ``score``
are kept, overlapping ones of one class (IoU above ``iou``) reduced to the best (non-maximum
suppression, :func:`cv2.dnn.NMSBoxesBatched`).

A box's reference pixel is its bottom centre by default (where an upright object stands on the
ground; ``point="centre"`` for objects lying flat, seen from above). Its ground area is the box's
pixels times the ground footprint of a pixel there (three rays of the job's stop rule).
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..rules import StopRule
from ..sensor.model import Pose, SensorModel
from .motion import Blobs

POINTS = ("bottom", "centre")


class LearnedDetector:
    """``path``: the ONNX model; ``score``: the least score kept; ``iou``: the overlap above which
    boxes of one class are one; ``classes``: the class names kept (None: all); ``point``: the
    reference pixel, "bottom" (centre of the box's bottom edge) or "centre"."""

    def __init__(self, path: str | Path, rule: StopRule, *, score: float = 0.35, iou: float = 0.5,
                 classes: set[str] | None = None, point: str = "bottom") -> None:
        from ..util.extras import require

        require("onnxruntime")  # (an optional part: the message says how to get it)
        import onnxruntime as ort

        if point not in POINTS:
            raise ValueError(f"point must be one of {POINTS}, got {point!r}")
        path = Path(path)
        if not path.is_file():
            raise InputError(f"{path}: no such model file")
        try:
            self.session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime's own errors (InvalidGraph, Fail, ...) have no common base
            raise InputError(f"{path}: not an ONNX model onnxruntime can run ({exc.__class__.__name__}: "
                             f"{str(exc).splitlines()[0] if str(exc) else ''})") from exc
        inp = self.session.get_inputs()[0]
        shape = list(inp.shape)
        if len(shape) != 4 or (isinstance(shape[1], int) and shape[1] != 3):
            raise InputError(f"{path}: its input {inp.name!r} is {shape}, not an image batch (1, 3, H, W)")
        self.input_name = inp.name
        self.size = (shape[3] if isinstance(shape[3], int) else 640, shape[2] if isinstance(shape[2], int) else 640)
        meta = self.session.get_modelmeta().custom_metadata_map
        self.names = _names(meta.get("names", ""))
        self.rule, self.score, self.iou, self.classes, self.point = rule, score, iou, classes, point

    def class_name(self, k: int) -> str:
        return self.names.get(k, f"class_{k}")

    def detect(self, index: int, time_s: float, image: np.ndarray, sensor: SensorModel, pose: Pose) -> Blobs:
        """The boxes of one frame (image (H, W) or (H, W, 3) uint8, full size) as :class:`Blobs`
        (``label``: class names, ``score``: their scores)."""
        import cv2

        img = image if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
        h, w = img.shape[:2]
        W, H = self.size
        r = min(W / w, H / h)
        nw, nh = round(w * r), round(h * r)
        px, py = (W - nw) // 2, (H - nh) // 2
        canvas = np.full((H, W, 3), 114, np.uint8)
        canvas[py:py + nh, px:px + nw] = cv2.resize(img, (nw, nh), interpolation=cv2.INTER_LINEAR)
        x = np.ascontiguousarray(canvas.transpose(2, 0, 1)[None], dtype=np.float32) / 255.0
        out = np.asarray(self.session.run(None, {self.input_name: x})[0], dtype=np.float32)
        boxes, scores, cls = _decode(out)
        keep = scores >= self.score
        if self.classes is not None:
            keep &= np.isin(np.array([self.class_name(int(k)) for k in cls]), list(self.classes))
        boxes, scores, cls = boxes[keep], scores[keep], cls[keep]
        if scores.size:
            xywh = np.c_[boxes[:, 0] - boxes[:, 2] / 2, boxes[:, 1] - boxes[:, 3] / 2, boxes[:, 2], boxes[:, 3]]
            chosen = cv2.dnn.NMSBoxesBatched(xywh.tolist(), scores.tolist(), cls.astype(int).tolist(), self.score,
                                             self.iou)
            chosen = np.asarray(chosen, dtype=np.intp).ravel()
            boxes, scores, cls = boxes[chosen], scores[chosen], cls[chosen]
        # input pixels -> the frame's (edges: the image spans 0..w), then eoloc's pixel centres
        x0 = np.clip((boxes[:, 0] - boxes[:, 2] / 2 - px) / r, 0, w)
        x1 = np.clip((boxes[:, 0] + boxes[:, 2] / 2 - px) / r, 0, w)
        y0 = np.clip((boxes[:, 1] - boxes[:, 3] / 2 - py) / r, 0, h)
        y1 = np.clip((boxes[:, 1] + boxes[:, 3] / 2 - py) / r, 0, h)
        u = (x0 + x1) / 2 - 0.5
        v = (y1 if self.point == "bottom" else (y0 + y1) / 2) - 0.5
        area_px = (x1 - x0) * (y1 - y0)
        area_m2 = area_px * _pixel_m2(sensor, pose, self.rule, u, v)
        box = np.c_[np.floor(x0), np.floor(y0), np.ceil(x1) - 1, np.ceil(y1) - 1].astype(int).reshape(-1, 4)
        at_edge = (x0 <= 0) | (y0 <= 0) | (x1 >= w) | (y1 >= h)
        n = u.size
        return Blobs(index, float(time_s), u, v, box, area_px, area_m2, scores.astype(float), np.zeros(n, np.int8),
                     at_edge, np.zeros((0, 2)), 1.0, label=np.array([self.class_name(int(k)) for k in cls], object),
                     score=scores.astype(float))


def _names(text: str) -> dict[int, str]:
    """Ultralytics' ``names`` metadata ("{0: 'person', 1: 'car'}") as a dict; {} when absent or
    not such a dict."""
    try:
        d = ast.literal_eval(text) if text else {}
    except (ValueError, SyntaxError):
        return {}
    return {int(k): str(v) for k, v in d.items()} if isinstance(d, dict) else {}


def _decode(out: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """YOLO output -> boxes (N, 4) cx, cy, w, h (input pixels), scores (N,), classes (N,)."""
    a = out[0] if out.ndim == 3 else out
    if a.ndim != 2:
        raise InputError(f"the model's output is {out.shape}: not YOLO detections (1, 4 + C, N) or (1, N, 5 + C)")
    if a.shape[0] < a.shape[1] and a.shape[0] >= 5:  # (4 + C, N): YOLOv8 / v11
        a = a.T
        cls_scores = a[:, 4:]
    elif a.shape[1] >= 6:  # (N, 5 + C): YOLOv5 / v7, objectness first
        cls_scores = a[:, 5:] * a[:, 4:5]
    elif a.shape[1] == 5:  # (N, 5): one class, its score
        cls_scores = a[:, 4:5]
    else:
        raise InputError(f"the model's output is {out.shape}: not YOLO detections (1, 4 + C, N) or (1, N, 5 + C)")
    cls = np.argmax(cls_scores, axis=1)
    return a[:, :4], cls_scores[np.arange(a.shape[0]), cls], cls


def _pixel_m2(sensor: SensorModel, pose: Pose, rule: StopRule, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The ground area of one pixel at each (u, v): the cross product of the ground steps to its
    right and below (NaN where a ray does not reach the ground)."""
    if u.size == 0:
        return np.zeros(0)
    from ..geodesy import geodetic_to_ecef

    c = sensor.camera  # the pixel and its neighbours, kept inside the image
    u = np.clip(u, 0, c.width - 2)
    v = np.clip(v, 0, c.height - 2)
    f = rule.locate(sensor, pose, (np.r_[u, u + 1, u], np.r_[v, v, v + 1]))
    p = np.stack(geodetic_to_ecef(f.lat_deg, f.lon_deg, f.h_m), -1).reshape(3, -1, 3)
    return np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0]), axis=-1)
