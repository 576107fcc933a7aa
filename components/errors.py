"""Errors shared by the SDK, the components and the orchestrator."""

import re

# numpy 2 scalars print as np.float64(0.5): a message shows the number a person wrote
_NUMPY_SCALAR = re.compile(r"np\.(?:float|int|uint|bool|complex|str)\w*\(([^()]*)\)")


def plain(text: str) -> str:
    """``text`` with numpy scalar reprs (``np.float64(0.5)``) shown as their values (``0.5``)."""
    return _NUMPY_SCALAR.sub(r"\1", text)


class ConfigError(Exception):
    """A configuration problem, tied to the config key that causes it.

    ``key`` is relative to where it is raised (a component parameter name, say); callers that
    know more of the path put their prefix in front of it.
    """

    def __init__(self, key: str, message: str):
        message = plain(message)
        super().__init__(f"{key}: {message}" if key else message)
        self.key = key
        self.message = message


class ComponentError(Exception):
    """A component failed while running (raised inside do_step, initialize, ...)."""

    def __init__(self, message: str = ""):
        super().__init__(plain(str(message)))
