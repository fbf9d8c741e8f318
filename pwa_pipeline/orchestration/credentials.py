"""Credentials in a tracking URI (``http://user:password@host``): kept out of messages,
logs and stored run configuration, sent as HTTP basic authentication."""

import base64
import os
import urllib.parse

#: The environment variables MLflow reads its HTTP basic authentication from.
USERNAME_ENV, PASSWORD_ENV = "MLFLOW_TRACKING_USERNAME", "MLFLOW_TRACKING_PASSWORD"


def user_and_password(uri: str) -> tuple[str, str | None, str | None]:
    """``(uri without user:password@, user, password)``; ``None`` for what is not given."""
    parts = urllib.parse.urlsplit(uri)
    if parts.username is None:
        return uri, None, None
    host = parts.hostname + (f":{parts.port}" if parts.port else "")
    password = None if parts.password is None else urllib.parse.unquote(parts.password)
    return (urllib.parse.urlunsplit(parts._replace(netloc=host)),
            urllib.parse.unquote(parts.username), password)


def split_credentials(uri: str) -> tuple[str, str]:
    """``(uri without user:password@, base64 'user:password' or '')``: the credentials of
    the URI, else those of ``$MLFLOW_TRACKING_USERNAME`` and ``$MLFLOW_TRACKING_PASSWORD``
    (where `credentials_to_environment` put them)."""
    url, user, password = user_and_password(uri)
    if user is None:
        user, password = os.environ.get(USERNAME_ENV), os.environ.get(PASSWORD_ENV)
    if not user:
        return url, ""
    return url, base64.b64encode(f"{user}:{password or ''}".encode()).decode()


def mask_credentials(uri: str) -> str:
    """``uri`` with a password replaced by ``***``, for messages and logs."""
    parts = urllib.parse.urlsplit(uri)
    if parts.password is None:
        return uri
    return urllib.parse.urlunsplit(parts._replace(
        netloc=parts.netloc.replace(f":{parts.password}@", ":***@", 1)))


def credentials_to_environment(uri: str) -> str:
    """``uri`` without its ``user:password@``, which go to ``$MLFLOW_TRACKING_USERNAME`` and
    ``$MLFLOW_TRACKING_PASSWORD`` of this process (and of the processes it starts), where
    MLflow reads them.

    A resource's configured value is stored in every run's job snapshot, which the Dagster
    UI shows and any reader of its storage (sqlite or PostgreSQL) sees: what is configured
    must hold no secret, so the password travels only in the environment.

    Parameters
    ----------
    uri : str
        A tracking URI, with or without credentials.

    Returns
    -------
    str
        The URI without credentials (``uri`` itself when it has none).
    """
    url, user, password = user_and_password(uri)
    if user is not None:
        os.environ[USERNAME_ENV] = user
        os.environ[PASSWORD_ENV] = password or ""
    return url
