"""Errors shared by the SDK, the components and the orchestrator."""


class ConfigError(Exception):
    """A configuration problem, tied to the config key that causes it.

    ``key`` is relative to where it is raised (a component parameter name, say); callers that
    know more of the path put their prefix in front of it.
    """

    def __init__(self, key: str, message: str):
        super().__init__(f"{key}: {message}" if key else message)
        self.key = key
        self.message = message


class ComponentError(Exception):
    """A component failed while running (raised inside do_step, initialize, ...)."""
