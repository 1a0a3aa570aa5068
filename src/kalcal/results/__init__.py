"""The result of each command, typed first and serialized last: the base classes a scenario's own result extends."""
