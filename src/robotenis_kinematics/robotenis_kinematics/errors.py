"""The error every reader of a robot description raises (description, effects)."""


class DescriptionError(ValueError):
    """A robot description that cannot be used; the message names the offending key."""
