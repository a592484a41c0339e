"""The one exception for user mistakes (kept import-free so the CLI starts fast)."""


class ConfigError(Exception):
    """A user mistake in a config or on the command line: the message names the file and
    the key; the CLI prints it as one line and exits with status 2."""


class Interrupted(Exception):
    """Ctrl-C during a run; the message says what was kept."""
