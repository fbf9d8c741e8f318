"""Credentials in a tracking URI: split off for HTTP basic authentication, masked in messages."""

import base64

from pwa_pipeline.orchestration.credentials import (
    mask_credentials,
    split_credentials,
    user_and_password,
)


def test_user_and_password_are_split_off_and_unquoted():
    assert user_and_password("http://ana:s%40cret@host:5000/x") == (
        "http://host:5000/x", "ana", "s@cret")
    assert user_and_password("http://ana@host") == ("http://host", "ana", None)
    assert user_and_password("http://host:5000") == ("http://host:5000", None, None)
    assert user_and_password("sqlite:////tmp/m.db") == ("sqlite:////tmp/m.db", None, None)


def test_the_basic_authentication_token_is_user_colon_password():
    url, token = split_credentials("https://ana:s%40cret@host/")
    assert url == "https://host/" and base64.b64decode(token) == b"ana:s@cret"
    assert split_credentials("https://host/") == ("https://host/", "")


def test_a_password_is_masked_and_nothing_else_changes():
    assert mask_credentials("http://ana:s3cret@host:5000") == "http://ana:***@host:5000"
    assert mask_credentials("http://host:5000") == "http://host:5000"
