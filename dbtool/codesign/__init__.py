"""Co-design (SPEC sections 4-6): embedding optimisation and diffusion as co-design."""
