"""Errors every layer may raise: a leaf module (imports nothing of the package)."""

from __future__ import annotations


class ConfigError(ValueError):
    """Invalid configuration; ``errors`` holds one message per problem ("path: got X; expected Y")."""

    def __init__(self, errors: list[str]):
        self.errors = list(errors)
        # one problem: one line (what a command prints after "error: "); several: one line each
        super().__init__(self.errors[0] if len(self.errors) == 1 else
                         f"{len(self.errors)} problems:\n  " + "\n  ".join(self.errors))
