"""User-facing errors: one clear line naming the key, the bad value and what is allowed."""

from __future__ import annotations


class ConfigError(ValueError):
    """A configuration value that cannot work; raised before any training or output."""

    def __init__(self, key: str, value, allowed: str):
        self.key, self.value, self.allowed = key, value, allowed
        super().__init__(f"{key}={value!r} is not allowed: expected {allowed}")

    def __reduce__(self):
        """Picklable with its three fields: launchers (joblib, submitit) send a failed job's error home."""
        return type(self), (self.key, self.value, self.allowed)
