"""Errors shared by the SDK, the components and the orchestrator."""


class ConfigError(Exception):
    """A configuration problem, tied to the config key that causes it.

    ``key`` is relative to where it is raised (a component parameter name, say); callers that
    know more of the path prefix it with :meth:`under`.
    """

    def __init__(self, key: str, message: str):
        super().__init__(f"{key}: {message}" if key else message)
        self.key = key
        self.message = message

    def under(self, prefix: str) -> "ConfigError":
        return ConfigError(f"{prefix}.{self.key}" if self.key else prefix, self.message)


class ComponentError(Exception):
    """A component failed while running (raised inside do_step, initialize, ...)."""
