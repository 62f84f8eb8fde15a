"""Scene files: TOML in, a :class:`~contactlab.model.Model` and how to simulate it out.

    from contactlab.scene import load_scene, builtin_scenes
    scene = load_scene("bouncing_ball", overrides=["simulation.dt=0.0005"])
    scene.model, scene.method, scene.dt, scene.duration, scene.integrator, scene.options

The format is described in ``docs/scene-format.md``. Modules, one concern each:

* :mod:`.toml`: reading TOML text (syntax errors with line and column);
* :mod:`.overrides`: ``--set PATH=VALUE`` applied to the raw dict;
* :mod:`.schema`: the declarative schema and the structural/type checks;
* :mod:`.build`: a validated dict → ModelBuilder → Model (``array`` copies expanded);
* :mod:`.loader`: built-in names and paths, :class:`Scene`, :func:`load_scene`.
"""

from .loader import Scene, builtin_scenes, load_scene

__all__ = ["Scene", "builtin_scenes", "load_scene"]
