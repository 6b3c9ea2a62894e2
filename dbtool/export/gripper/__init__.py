"""The gripper's parts: the designed finger, its mirror copy and the base plate (``parts.py``),
with mounting holes and alignment pins, tendon routing points and the channels cut for them."""
