"""A scene's material: the config's, with the scene's own merged over it, and the numbers derived
from it that more than one part of the workflow needs (lc/h)."""

from __future__ import annotations

import math

#: the coarsest mesh accepted for a scene: AT2's profile exp(-|x|/lc) over at least two elements a
#: length scale (the paper's scenes have 6 to 9; the stability sweep probes 3)
MIN_LC_OVER_H = 2.0


def scene_material(material: dict, scene: dict) -> dict:
    """The material a run of ``scene`` uses: the config's, with the scene's own ``material`` merged
    over it (E and nu become the Lame pair: lambda = E nu / ((1 + nu)(1 - 2 nu)), mu = E / (2 (1 +
    nu))), and the scene's ``plane`` and ``thickness`` where it sets them (so a scene that sets none
    resolves to the config's material exactly)."""
    resolved = dict(material)
    own = dict(scene.get("material", {}))
    if "E" in own and "nu" in own:   # (E alone is refused by the checks)
        E, nu = own.pop("E"), own.pop("nu")
        own["lame_lambda"], own["lame_mu"] = E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))
    resolved.update(own)
    for key in ("plane", "thickness"):
        if key in scene:
            resolved[key] = scene[key]
    return resolved


def element_width(scene: dict) -> float:
    """The width h (mm) of a scene's elements along x (the config checks refuse elements that are not square)."""
    return (scene["domain"]["x"][1] - scene["domain"]["x"][0]) / scene["elements"][0]


def lc_over_h(material: dict, scene: dict) -> float:
    """lc / h of a run of ``scene`` with the config's ``material``: the scene's own lc (:func:`scene_material`)
    over its element width."""
    return scene_material(material, scene)["lc"] / element_width(scene)


def material_problems(material: dict, scene: dict, name: str) -> list[str]:
    """What the config refuses in the material of a run of scene ``name`` (config key 'scenes.NAME'),
    its domain valid: an lc the mesh cannot resolve (below MIN_LC_OVER_H elements) or not smaller than
    the specimen, and elastic constants given by halves or twice (E and nu, or the Lame pair)."""
    (x0, x1), (y0, y1) = scene["domain"]["x"], scene["domain"]["y"]
    key, problems = f"scenes.{name}", []
    h, lc = element_width(scene), scene_material(material, scene)["lc"]
    lc_key = f"{key}.material.lc" if "lc" in scene.get("material", {}) else "material.lc"
    if lc < MIN_LC_OVER_H * h:
        problems.append(f"config key '{lc_key}': lc = {lc:g} mm is {lc / h:.3g} elements of scene '{name}' "
                        f"(h = {h:g} mm); the mesh resolves the phase field from lc/h = {MIN_LC_OVER_H:g} on: "
                        f"refine the scene's elements to at least {math.ceil(MIN_LC_OVER_H * (x1 - x0) / lc)} across x")
    if lc >= min(x1 - x0, y1 - y0):
        problems.append(f"config key '{lc_key}': lc = {lc:g} mm is not smaller than scene '{name}' "
                        f"({x1 - x0:g} x {y1 - y0:g} mm): the phase field would span the specimen")
    own = scene.get("material", {})
    if ("E" in own) != ("nu" in own):
        problems.append(f"config key '{key}.material': give E and nu together (or lame_lambda and lame_mu), got {sorted(own)}")
    if ("E" in own) and ({"lame_lambda", "lame_mu"} & set(own)):
        problems.append(f"config key '{key}.material': give either E and nu or lame_lambda and lame_mu, not both")
    if ("lame_lambda" in own) != ("lame_mu" in own):
        problems.append(f"config key '{key}.material': give lame_lambda and lame_mu together, got {sorted(own)}")
    return problems
