"""A tiny ONNX object detector built with onnx's own helpers (nothing downloaded), for the tests
of the learned detector (eoloc video/live --detect MODEL.onnx)."""

from __future__ import annotations

import numpy as np


def yellow_model(path, width: int = 640, height: int = 384) -> None:
    """A tiny YOLOv8-style detector, built here with onnx's helpers (nothing downloaded): per 4 x 4
    cell the yellowest pixel (R + G - 2B, a 1 x 1 convolution then max pooling) squashed into a
    score; every cell proposes a 24 x 24 box on its centre. Output (1, 4 + 1, N), class 'vehicle'
    in the metadata as Ultralytics writes it."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    gw, gh = width // 4, height // 4
    cx, cy = np.meshgrid((np.arange(gw) + 0.5) * 4, (np.arange(gh) + 0.5) * 4)
    boxes = np.stack([cx.ravel(), cy.ravel(), np.full(gw * gh, 24.0), np.full(gw * gh, 24.0)])[None]
    inits = [numpy_helper.from_array(np.array([1.0, 1.0, -2.0], np.float32).reshape(1, 3, 1, 1), "w"),
             numpy_helper.from_array(np.array([1.2], np.float32), "t"),
             numpy_helper.from_array(np.array([20.0], np.float32), "k"),
             numpy_helper.from_array(np.array([1, 1, gw * gh], np.int64), "shape"),
             numpy_helper.from_array(boxes.astype(np.float32), "boxes")]
    nodes = [helper.make_node("Conv", ["images", "w"], ["yellow"]),
             helper.make_node("MaxPool", ["yellow"], ["cell"], kernel_shape=[4, 4], strides=[4, 4]),
             helper.make_node("Sub", ["cell", "t"], ["d"]), helper.make_node("Mul", ["d", "k"], ["z"]),
             helper.make_node("Sigmoid", ["z"], ["s"]), helper.make_node("Reshape", ["s", "shape"], ["score"]),
             helper.make_node("Concat", ["boxes", "score"], ["output0"], axis=1)]
    graph = helper.make_graph(nodes, "yellow", [helper.make_tensor_value_info("images", TensorProto.FLOAT,
                                                                               [1, 3, height, width])],
                              [helper.make_tensor_value_info("output0", TensorProto.FLOAT, [1, 5, gw * gh])], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    helper.set_model_props(model, {"names": "{0: 'vehicle'}"})
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
