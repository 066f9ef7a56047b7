"""Write a trained policy as an ONNX model with its metadata (training only: needs `onnx`)."""
from __future__ import annotations

from pathlib import Path

from controller_manager_py.controllers.policy_model import PolicyMetadata


def write_mlp_onnx(path, layers, axis_inputs: int, axes: int, metadata: PolicyMetadata) -> None:
    """Write a tanh MLP shared by `axes` axes as ONNX: input [batch, axes * axis_inputs] ->
    per-axis rows -> Gemm/Tanh layers (weights: [(W [out, in], b [out]), ...]) -> [batch, axes].
    Needs the `onnx` package (training only)."""
    import numpy as np
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    n_in = axes * axis_inputs
    nodes, inits = [], []
    inits.append(numpy_helper.from_array(np.array([-1, axis_inputs], dtype=np.int64), "rows_shape"))
    inits.append(numpy_helper.from_array(np.array([-1, axes], dtype=np.int64), "out_shape"))
    nodes.append(helper.make_node("Reshape", ["obs", "rows_shape"], ["h0"]))
    current = "h0"
    for i, (w, b) in enumerate(layers):
        inits.append(numpy_helper.from_array(np.asarray(w, dtype=np.float32), f"w{i}"))
        inits.append(numpy_helper.from_array(np.asarray(b, dtype=np.float32), f"b{i}"))
        nodes.append(helper.make_node("Gemm", [current, f"w{i}", f"b{i}"], [f"g{i}"], transB=1))
        nodes.append(helper.make_node("Tanh", [f"g{i}"], [f"h{i + 1}"]))
        current = f"h{i + 1}"
    nodes.append(helper.make_node("Reshape", [current, "out_shape"], ["action"]))
    graph = helper.make_graph(nodes, "policy",
                              [helper.make_tensor_value_info("obs", TensorProto.FLOAT, ["batch", n_in])],
                              [helper.make_tensor_value_info("action", TensorProto.FLOAT, ["batch", axes])], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], producer_name="ball_balance")
    model.ir_version = 8
    for key, value in metadata.props().items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.checker.check_model(model)
    Path(path).write_bytes(model.SerializeToString())
