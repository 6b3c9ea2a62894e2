"""Robotizing (SPEC section 2): a (noisy) surface cloud becomes a simulatable robot."""
