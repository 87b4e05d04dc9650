"""Exceptions that carry a message fit to show a user as is."""


class RadError(ValueError):
    """Bad input or an impossible request; str(error) names the problem."""


class SceneError(RadError):
    """A scene document or message that does not describe a valid scene."""

    def __init__(self, field: str, problem: str):
        self.field = field
        self.problem = problem
        super().__init__(f'{field}: {problem}' if field else problem)
