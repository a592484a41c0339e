"""The exceptions the CLI turns into one line and an exit status (kept import-free so the
CLI starts fast); docs/faults.md lists the statuses."""


class ConfigError(Exception):
    """A user mistake in a config or on the command line, or an output refused before the
    run: the message names the file and the key; the CLI prints it as one line and exits
    with status 2."""


class WriteError(Exception):
    """A fault while writing an archive, checkpoint or figure (disk full, no permission,
    I/O error): the message names the path and the OS reason; exit status 1. What was
    finished before is kept."""


class Interrupted(Exception):
    """A run stopped by SIGINT, SIGTERM, SIGHUP or its time limit; the message says what
    was kept and how to resume. ``code``: 130 (SIGINT) or 143 (SIGTERM, SIGHUP, time)."""

    def __init__(self, message: str, code: int = 130) -> None:
        super().__init__(message)
        self.code = code
