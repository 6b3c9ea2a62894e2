"""From parts to a printer: each part's print pose, the 3MF writer, PrusaSlicer's check and a
maker's check of an export folder from its files alone."""
