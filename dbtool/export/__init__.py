"""Export for fabrication (SPEC section 8): watertight meshes in millimetres."""
