"""Error types that the CLI turns into exit statuses.

``CaseError`` means the user's input is wrong (exit 2, one line, no traceback);
``NumericalFailure`` means a solver could not recover (exit 1, says what was tried).
"""

from __future__ import annotations


class CaseError(Exception):
    """Invalid user input: names the file and the dotted key at fault."""

    def __init__(self, file: str | None, key: str | None, message: str):
        self.file = file
        self.key = key
        self.message = message
        super().__init__(self.line())

    def line(self) -> str:
        where = str(self.file) if self.file else "<input>"
        if self.key:
            where += f": {self.key}"
        return f"{where}: {self.message}"


class NumericalFailure(Exception):
    """A solver failed and every recovery that was tried failed too."""
