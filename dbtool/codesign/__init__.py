"""Co-design (docs/method.md §4-§6): embedding optimisation and diffusion as co-design."""
