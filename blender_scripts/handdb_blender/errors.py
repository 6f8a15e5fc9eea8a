"""The one error type of the render scripts: bad outside input or a failed render step."""


class RenderError(Exception):
    """Printed by render.py as one line `handdb-render: <message>`, exit status 1."""
