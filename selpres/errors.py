"""User-facing errors: one clear line naming the key, the bad value and what is allowed."""

from __future__ import annotations

from pathlib import Path


class ConfigError(ValueError):
    """A configuration value that cannot work; raised before any training or output."""

    def __init__(self, key: str, value, allowed: str):
        self.key, self.value, self.allowed = key, value, allowed
        super().__init__(f"{key}={value!r} is not allowed: expected {allowed}")

    def __reduce__(self):
        """Picklable with its three fields: launchers (joblib, submitit) send a failed job's error home."""
        return type(self), (self.key, self.value, self.allowed)


class FileError(ConfigError):
    """A file selpres cannot use: one line naming the file, where in it (column, row, element) and the problem."""

    def __init__(self, path, where: str, problem: str):
        self.path, self.where, self.problem = str(path), where, problem
        self.key, self.value, self.allowed = f"{path}: {where}", None, problem
        ValueError.__init__(self, f"{path}: {where}: {problem}")

    def __reduce__(self):
        return type(self), (self.path, self.where, self.problem)


def not_a_file(path) -> str:
    """What stands at ``path`` where a file was wanted, for a :class:`FileError`'s problem: a directory, something
    that is not a regular file (a FIFO, socket or device), or nothing."""
    p = Path(path)
    if p.is_dir():
        return "is a directory, not a file"
    if p.exists():
        return "is not a regular file (a FIFO, socket or device)"
    return "not found"
