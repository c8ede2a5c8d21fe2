"""The package's shape: the imports that would make its parts depend on each other backwards."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "ifenn"


def _imports(path: Path):
    """(module imported from, names) of every ``from ifenn... import ...`` in ``path``."""
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("ifenn"):
            yield node.module, [alias.name for alias in node.names]
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("ifenn"):
                    yield alias.name, []


def _package_of(module: str, root: Path) -> str:
    """ifenn.fem.solver -> ifenn.fem (a sub-package); ifenn.config -> ifenn (a top-level module)."""
    parts = module.split(".")
    return ".".join(parts[:2]) if len(parts) > 1 and (root / parts[1]).is_dir() else "ifenn"


def _problems(root: Path) -> list[str]:
    problems = []
    for path in sorted(root.rglob("*.py")):
        here = "ifenn." + ".".join(path.relative_to(root).with_suffix("").parts)
        for module, names in _imports(path):
            if _package_of(module, root) != _package_of(here, root):
                problems += [f"{here} imports private {module}.{name}" for name in names if name.startswith("_")]
            if here.startswith("ifenn.fem.") and (module == "ifenn.config" or module.startswith("ifenn.config.")):
                problems.append(f"{here} imports {module}: the solver must not climb back to the config")
    return problems


STENCIL = {"LAPLACIAN_K9_STAR", "LAPLACIAN_CENTRE_WEIGHT", "STENCIL_LINKS"}


def _stencil_users(root: Path) -> list[str]:
    """The modules that import the pixel equation's stencil: the pixel equation's own only (ifenn.pixels
    defines it, with the slits' cut links)."""
    users = []
    for path in sorted(root.rglob("*.py")):
        here = "ifenn." + ".".join(path.relative_to(root).with_suffix("").parts)
        if any(STENCIL & set(names) for _, names in _imports(path)) and not here.startswith("ifenn.pixel_equation."):
            users.append(here)
    return users


def test_the_pixel_equation_is_written_in_one_package():
    assert _stencil_users(PACKAGE) == []


def test_no_private_name_crosses_a_package_and_fem_does_not_import_the_config():
    assert _problems(PACKAGE) == []


def test_the_layout_check_can_fail(tmp_path):
    (tmp_path / "fem").mkdir()
    (tmp_path / "studies").mkdir()
    (tmp_path / "fem" / "solver.py").write_text("from ifenn.config import spec_hash\n")
    (tmp_path / "studies" / "table.py").write_text("from ifenn.hybrid.runs import _hidden\n")
    assert _problems(tmp_path) == ["ifenn.fem.solver imports ifenn.config: the solver must not climb back to the config",
                                   "ifenn.studies.table imports private ifenn.hybrid.runs._hidden"]
    (tmp_path / "hybrid").mkdir()
    (tmp_path / "hybrid" / "step.py").write_text("from ifenn.pixels import LAPLACIAN_K9_STAR\n")
    assert _stencil_users(tmp_path) == ["ifenn.hybrid.step"]
