"""Export for fabrication (docs/method.md §8): watertight meshes in millimetres.

The stage (``assembly.py``) and its settings (``config.py``) sit at the top; the parts of the
work are subpackages: ``geometry`` (fields, meshes, voxels, infill), ``gripper`` (the gripper's
parts, mounting, tendons and channels), ``printing`` (print pose, 3MF, slicer, a maker's check)
and ``reports`` (report, assembly sheet, drawings)."""
