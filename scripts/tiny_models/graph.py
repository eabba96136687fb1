"""Building ONNX graphs node by node (onnx.helper; no torch)."""

import numpy as np
import onnx
from onnx import helper, numpy_helper

from .constants import IR_VERSION, OPSET


class GraphBuilder:
    """Accumulates nodes and constant initialisers; every op returns its output tensor name."""

    def __init__(self):
        self.nodes = []
        self.initializers = []
        self._count = 0

    def _fresh(self, hint):
        self._count += 1
        return f"{hint}_{self._count}"

    def const(self, value, dtype=np.float32, hint="const"):
        name = self._fresh(hint)
        self.initializers.append(numpy_helper.from_array(np.asarray(value, dtype=dtype), name))
        return name

    def i64(self, value, hint="shape"):
        return self.const(value, np.int64, hint)

    def op(self, op_type, *inputs, output=None, **attrs):
        out = output or self._fresh(op_type.lower())
        self.nodes.append(helper.make_node(op_type, list(inputs), [out], **attrs))
        return out

    def reduce_sum(self, x, axes, keepdims):
        # opset 13+: ReduceSum takes axes as an input
        return self.op("ReduceSum", x, self.i64(axes), keepdims=keepdims)

    def l2_normalise(self, x, output):
        squared = self.reduce_sum(self.op("Mul", x, x), [1], keepdims=1)
        norm = self.op("Sqrt", self.op("Add", squared, self.const(1e-12)))
        return self.op("Div", x, norm, output=output)

    def model(self, name, inputs, outputs):
        graph = helper.make_graph(self.nodes, name, inputs, outputs, self.initializers)
        model = helper.make_model(
            graph,
            opset_imports=[helper.make_opsetid("", OPSET)],
            producer_name="segsplat make_tiny_models.py",
        )
        model.ir_version = IR_VERSION
        onnx.checker.check_model(model, full_check=True)
        return model


def tensor_info(name, elem_type, shape):
    """Value info with symbolic names for the dynamic (-1) dimensions."""
    dims = [f"{name}_dim{i}" if d == -1 else d for i, d in enumerate(shape)]
    return helper.make_tensor_value_info(name, elem_type, dims)
