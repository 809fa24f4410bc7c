"""kbcli: where is my keyboard? Model-based active adaptation of a robot's action space.

A command-line pipeline reproducing Ribes et al., "Where is my keyboard? Model-based active
adaptation of action-space in a humanoid robot": a robot arm that learned where the notes of a
virtual keyboard are notices that the keyboard moved and recovers the displacement with few,
well-chosen touches.
"""

__version__ = "0.1.0"
