"""Domain errors. The CLI prints them on one line and exits 1; everything else is a bug."""


class KbcliError(Exception):
    """A user-facing error: bad input, bad config, an artifact that cannot be used."""


class ConfigError(KbcliError, ValueError):
    """An invalid configuration value; the message names the option and what is allowed."""


class ArtifactError(KbcliError):
    """An artifact file that is missing, unreadable, of the wrong kind or of a newer schema."""


class OutOfReachError(KbcliError):
    """A target outside the arm's workspace (never silently clipped)."""


class ObservationError(KbcliError, ValueError):
    """An observation the adaptation cannot use (non-numeric features, an action outside the
    working area); nothing is updated."""
