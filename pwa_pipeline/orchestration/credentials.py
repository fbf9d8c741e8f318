"""Credentials in a tracking URI (``http://user:password@host``): kept out of messages and
logs, sent as HTTP basic authentication."""

import base64
import urllib.parse


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
    """``(uri without user:password@, base64 'user:password' or '')``."""
    url, user, password = user_and_password(uri)
    if user is None:
        return url, ""
    return url, base64.b64encode(f"{user}:{password or ''}".encode()).decode()


def mask_credentials(uri: str) -> str:
    """``uri`` with a password replaced by ``***``, for messages and logs."""
    parts = urllib.parse.urlsplit(uri)
    if parts.password is None:
        return uri
    return urllib.parse.urlunsplit(parts._replace(
        netloc=parts.netloc.replace(f":{parts.password}@", ":***@", 1)))
