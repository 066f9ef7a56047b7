"""The packages' import graph: no cycles (imports only under TYPE_CHECKING aside), the
framework (controller_manager_py) imports nothing of the application (ball_balance), and
within the application no layer imports a higher one, nor an algorithm ROS."""
import ast
from pathlib import Path

from harness import ROOT

PACKAGES = {"controller_manager_py": ROOT / "controller_manager_py" / "controller_manager_py",
            "ball_balance": ROOT / "ball_balance"}
# ball_balance's layers, lowest first, by their first name under ball_balance: geometry, the
# algorithms (plain Python, no ROS), the learned policy and the configuration both the benchmark
# and the policy's training plant read; everything else (nodes, controllers, hardware, the
# benchmark, tools) is above them and may import any of them
LAYERS = [{"plate_geometry", "rotations", "robot"},
          {"control", "vision", "sim"},
          {"policy", "config_values"}]
ROS_MODULES = ("rclpy", "rcl_interfaces", "ament_index_python")


def _runtime_imports(tree: ast.AST):
    """ImportFrom / Import nodes, skipping `if TYPE_CHECKING:` blocks."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            continue
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        yield from _runtime_imports(node)


def _module_name(package: str, root: Path, path: Path) -> str:
    parts = [package, *path.relative_to(root).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports() -> dict:
    """module -> every name it imports at run time (modules and the names taken from them)."""
    graph = {}
    for package, root in PACKAGES.items():
        for path in root.rglob("*.py"):
            module = _module_name(package, root, path)
            is_package = path.name == "__init__.py"
            targets = set()
            for node in _runtime_imports(ast.parse(path.read_text())):
                if isinstance(node, ast.Import):
                    targets |= {a.name for a in node.names}
                    continue
                if node.level:
                    base = module.split(".")
                    base = base[:len(base) - node.level + (1 if is_package else 0)]
                    name = ".".join(base + ([node.module] if node.module else []))
                else:
                    name = node.module or ""
                targets |= {name} | {f"{name}.{a.name}" for a in node.names}
            graph[module] = targets
    return graph


def import_graph() -> dict:
    """module -> the modules of these packages it imports."""
    raw = imports()
    return {m: {t for t in targets if t in raw and t != m} for m, targets in raw.items()}


def _cycles(graph: dict) -> list:
    """Strongly connected components of more than one module (iterative Tarjan)."""
    index, low, on_stack, stack, found, counter = {}, {}, set(), [], [], [0]
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter[0]
        counter[0] += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, edges = work[-1]
            for nxt in edges:
                if nxt not in index:
                    index[nxt] = low[nxt] = counter[0]
                    counter[0] += 1
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(sorted(graph[nxt]))))
                    break
                if nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return found


def test_no_import_cycles():
    assert _cycles(import_graph()) == []


def test_the_framework_imports_nothing_of_the_application():
    offenders = {m: sorted(t for t in targets if t.split(".")[0] == "ball_balance")
                 for m, targets in imports().items() if m.startswith("controller_manager_py")}
    assert {m: t for m, t in offenders.items() if t} == {}


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def _layer(module: str) -> int:
    """The layer of a ball_balance module (len(LAYERS) above them all)."""
    name = module.split(".")[1] if "." in module else ""
    return next((i for i, layer in enumerate(LAYERS) if name in layer), len(LAYERS))


def test_no_layer_imports_a_higher_one():
    graph = import_graph()
    upward = {m: sorted(t for t in targets if t.startswith("ball_balance.") and _layer(t) > _layer(m))
              for m, targets in graph.items() if m.startswith("ball_balance.")}
    assert {m: t for m, t in upward.items() if t} == {}


def test_the_algorithms_import_no_ros():
    offenders = {m: sorted(t for t in targets if t.split(".")[0] in ROS_MODULES or t.split(".")[0].endswith("_msgs"))
                 for m, targets in imports().items() if m.startswith("ball_balance.") and _layer(m) < len(LAYERS)}
    assert {m: t for m, t in offenders.items() if t} == {}
