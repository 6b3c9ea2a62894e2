"""Export for fabrication (docs/method.md §8): watertight meshes in millimetres."""
