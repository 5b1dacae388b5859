"""Scenes: what the simulated probe touches, on which board, with which faults.

* :mod:`~firmware_sim.scene.model` -- the parsed scene (frozen dataclasses) and :class:`SceneError`;
* :mod:`~firmware_sim.scene.schema` -- each TOML table's fields as :class:`edge.schema.Field` data;
* :mod:`~firmware_sim.scene.parser` -- TOML text to a checked :class:`Scene` (``parse_scene``, ``validate_fault``);
* :mod:`~firmware_sim.scene.files` -- shipped scenes (``shipped/*.toml``), ``read_scene``, ``scene_variant``.

This package namespace exports nothing itself: import each name from its module.
"""
