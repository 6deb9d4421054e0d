"""Effects beyond the paper's geometry that a calibrated robot description can carry.

Each effect is a map ``{name: ..., <parameters>}`` in the description's ``effects`` list. The joint
effects turn resolver increments into true arm angles (``joint_angles``), which forward kinematics
then uses; the registry below names the known effects and the keys each must have.
"""
import numpy as np

from robotenis_kinematics.description import DescriptionError

# name -> required parameter keys (each a list of three numbers, one per joint)
MODELS = {}


def validate(effect, where):
    """Check one effect map; raises DescriptionError naming the key."""
    name = effect.get('name')
    if name not in MODELS:
        raise DescriptionError(f"{where}.name: unknown effect {name!r} (known: {', '.join(sorted(MODELS)) or 'none'})")


def joint_angles(desc, Theta):
    """True arm angles theta (N, 3) for resolver increments Theta (N, 3) visited in this order."""
    return desc.theta0 + np.asarray(Theta, dtype=float)
