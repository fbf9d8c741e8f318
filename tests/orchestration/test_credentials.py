"""Credentials in a tracking URI: split off for HTTP basic authentication, masked in messages."""

import base64
import os

from pwa_pipeline.orchestration.credentials import (
    PASSWORD_ENV,
    USERNAME_ENV,
    credentials_to_environment,
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


def test_the_basic_authentication_token_is_user_colon_password(monkeypatch):
    monkeypatch.delenv(USERNAME_ENV, raising=False)
    url, token = split_credentials("https://ana:s%40cret@host/")
    assert url == "https://host/" and base64.b64decode(token) == b"ana:s@cret"
    assert split_credentials("https://host/") == ("https://host/", "")


def test_a_password_is_masked_and_nothing_else_changes():
    assert mask_credentials("http://ana:s3cret@host:5000") == "http://ana:***@host:5000"
    assert mask_credentials("http://host:5000") == "http://host:5000"


def test_credentials_move_to_mlflow_variables_and_the_probe_reads_them(monkeypatch):
    """What is configured (and so stored with every run) is the URI without credentials;
    MLflow and the health probe find them in MLflow's own variables."""
    for name in (USERNAME_ENV, PASSWORD_ENV):
        monkeypatch.setenv(name, "")  # recorded, so that the test's end restores it
        monkeypatch.delenv(name)
    assert credentials_to_environment("http://ana:s%40cret@host:5000/") == "http://host:5000/"
    assert (os.environ[USERNAME_ENV], os.environ[PASSWORD_ENV]) == ("ana", "s@cret")
    url, token = split_credentials("http://host:5000/")
    assert url == "http://host:5000/" and base64.b64decode(token) == b"ana:s@cret"
    assert credentials_to_environment("http://other:5000") == "http://other:5000"
    assert os.environ[USERNAME_ENV] == "ana"  # a URI without credentials leaves them


class _Store:
    def __init__(self, url: str):
        self.url = url

    def root(self) -> str:
        return self.url

    def cache_root(self) -> str:
        return self.url + "/cache"

    def uri(self) -> str:
        return self.url


def test_the_run_configuration_sent_to_dask_workers_holds_no_password():
    """``--executor dask`` gives its workers the stores as run configuration, which every
    run stores and the UI shows: a store or tracking URL holding a password is left out
    (the workers read their own environment), one without is passed on."""
    from pwa_pipeline.orchestration.dask_sweep import worker_run_config

    secret = worker_run_config({"io_manager": _Store("sftp://ana:s3cret@host/pwa"),
                                "settings": _Store("sftp://ana:s3cret@host/pwa"),
                                "mlflow": _Store("http://ana:s3cret@host:5000")})
    assert "s3cret" not in repr(secret)
    plain = worker_run_config({"io_manager": _Store("/srv/pwa"), "settings": _Store("/srv/pwa"),
                               "mlflow": _Store("http://host:5000")})["resources"]
    assert plain == {"io_manager": {"config": {"base_dir": "/srv/pwa"}},
                     "settings": {"config": {"cache_dir": "/srv/pwa/cache"}},
                     "mlflow": {"config": {"tracking_uri": "http://host:5000"}}}
