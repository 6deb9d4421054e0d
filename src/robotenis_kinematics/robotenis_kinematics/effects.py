"""Effects beyond the paper's geometry that a calibrated description can carry (placeholder registry)."""
from robotenis_kinematics.description import DescriptionError

MODELS = {}


def validate(effect, where):
    """Check one effect map; raises DescriptionError naming the key."""
    name = effect.get('name')
    if name not in MODELS:
        raise DescriptionError(f"{where}.name: unknown effect {name!r} (known: {', '.join(sorted(MODELS)) or 'none'})")
