"""The layers, read from the source: which package may import which (ARCHITECTURE.md).

    core  <-  rfch, nav, hardware  <-  sim  <-  serial_twins  <-  app  <-  commands, cli
    (sim uses nav only for the maps it cuts from a scene; nav never imports sim)

Every import statement counts, also those inside functions (the project imports heavy modules
lazily), so a lazy import cannot smuggle a forbidden edge past the test.
"""

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DEVICE_LIBRARIES = {"mujoco", "rerun", "serial", "cv2", "ray", "matplotlib", "tqdm"}


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(path: Path) -> set[str]:
    """Every module ``path`` imports, as absolute dotted names."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = module_name(path).rsplit(".", 1)[0] if path.name != "__init__.py" else None
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against the package
                base = (package or module_name(path)).split(".")
                base = base[: len(base) - node.level + 1]
                found.add(".".join([*base, node.module] if node.module else base))
            elif node.module != "__future__":
                # "from hardware import vcc4_codec" imports the submodule, not the package
                for alias in node.names:
                    sub = f"{node.module}.{alias.name}"
                    is_module = (ROOT / sub.replace(".", "/")).with_suffix(".py").is_file()
                    found.add(sub if is_module else node.module)
    return found


def sources(*packages: str) -> dict[str, set[str]]:
    graph = {}
    for package in packages:
        for path in sorted((ROOT / package.replace(".", "/")).rglob("*.py")):
            graph[module_name(path)] = imports_of(path)
    return graph


def project(name: str) -> str | None:
    """The project layer a module belongs to, or None for a library."""
    parts = name.split(".")
    if parts[0] == "hardware":
        return "hardware.codec" if parts[-1].endswith("_codec") else "hardware"
    if parts[0] != "twin":
        return None
    if len(parts) == 1:
        return "twin"
    return f"twin.{parts[1]}"


def violations(graph, layer: str, allowed_layers: set[str], banned_libraries=frozenset()):
    found = []
    for module, imported in graph.items():
        if project(module) != layer:
            continue
        for name in imported:
            target = project(name)
            top = name.split(".")[0]
            if target is None and top in banned_libraries:
                found.append(f"{module} imports {name}")
            elif target is not None and target != layer and target not in allowed_layers:
                found.append(f"{module} imports {name} ({target})")
    return sorted(found)


GRAPH = sources("twin", "hardware")
RULES = {
    # layer: (project layers it may import, libraries it must not)
    "twin.core": (set(), DEVICE_LIBRARIES),
    "twin.rfch": ({"twin.core"}, DEVICE_LIBRARIES - {"cv2"}),
    "twin.nav": ({"twin.core"}, DEVICE_LIBRARIES),
    "hardware.codec": (set(), DEVICE_LIBRARIES),
    "hardware": ({"twin.core", "hardware.codec"}, {"mujoco", "rerun", "ray"}),
    # the twin builds maps (an OccupancyMap cut from the scene), so it may use twin.nav's types
    "twin.sim": ({"twin.core", "twin.resources", "twin.nav"}, {"rerun", "serial", "ray"}),
    "twin.serial_twins": ({"twin.core", "twin.sim", "hardware.codec"}, {"rerun", "ray"}),
    "twin.app": (
        {
            "twin",
            "twin.core",
            "twin.rfch",
            "twin.nav",
            "twin.sim",
            "twin.serial_twins",
            "twin.resources",
            "hardware",
            "hardware.codec",
        },
        set(),
    ),
    # the Gymnasium environment: a search mission (twin.app) in the twin's world
    "twin.envs": ({"twin", "twin.core", "twin.app", "twin.sim"}, set()),
}


@pytest.mark.parametrize("layer", sorted(RULES))
def test_a_layer_imports_only_what_is_below_it(layer):
    allowed, banned = RULES[layer]
    assert violations(GRAPH, layer, allowed, banned) == []


def test_every_module_belongs_to_a_known_layer():
    known = {*RULES, "twin", "twin.commands", "twin.cli", "twin.resources", "twin._data"}
    assert {project(m) for m in GRAPH} <= known


def test_only_the_command_line_imports_the_commands():
    offenders = [
        f"{m} imports {n}"
        for m, names in GRAPH.items()
        for n in names
        if project(n) == "twin.commands" and project(m) not in ("twin.commands", "twin.cli")
    ]
    assert offenders == []


def test_the_import_rules_catch_a_forbidden_edge():
    graph = {"twin.core.grid": {"numpy", "twin.app.run", "mujoco"}}
    assert violations(graph, "twin.core", set(), DEVICE_LIBRARIES) == [
        "twin.core.grid imports mujoco",
        "twin.core.grid imports twin.app.run (twin.app)",
    ]


def layer_graph() -> dict[str, set[str]]:
    """Which layer imports which (for people: ``python tests/test_layers.py``)."""
    edges: dict[str, set[str]] = {}
    for module, names in GRAPH.items():
        source = project(module)
        for name in names:
            target = project(name)
            if target and target != source:
                edges.setdefault(source, set()).add(target)
    return edges


if __name__ == "__main__":
    for source, targets in sorted(layer_graph().items()):
        sys.stdout.write(f"{source:18s} -> {', '.join(sorted(targets))}\n")
