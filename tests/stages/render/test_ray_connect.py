"""Joining Ray (:mod:`sweep3d.stages.render.ray_pool`) without a cluster: a run with nothing to
compute never joins one; a cluster that asks for a token this process does not send is one line
naming the fix (not 20 lines of ``InvalidAuthToken`` and a traceback); an explicit address gets
this user's token when there is one (``ray start`` turns token authentication on when there is)."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from sweep3d.core import UserError
from sweep3d.stages.render import ray_pool


class RefusingRay:
    """A stand-in for ``ray`` whose client is refused as Ray 2.60's is: a line a second from its
    C++ client on fd 2, then ``ConnectionError``."""

    def __init__(self, says: str) -> None:
        self.says = says

    def is_initialized(self) -> bool:
        return False

    def init(self, **_: object) -> None:
        for _ in range(20):
            os.write(2, f"[gcs_client.cc:210] Failed to get cluster ID from GCS server: {self.says}\n".encode())
        raise ConnectionError("Failed to connect to Ray cluster at 10.0.0.1:6379")


@pytest.mark.parametrize("says, words", [
    ("Unauthenticated: RPC error: InvalidAuthToken: Authentication token is missing or incorrect",
     "asks for an authentication token and this process sends none: set RAY_AUTH_TOKEN"),
    ("Unavailable: failed to connect to all addresses", "cannot join a Ray cluster there (Failed to connect"),
])
def test_a_refused_join_is_one_line_and_the_client_s_retries_stay_out_of_the_terminal(
        monkeypatch, capfd, says: str, words: str) -> None:
    monkeypatch.setattr(ray_pool, "_ray", lambda: RefusingRay(says))
    monkeypatch.setattr(ray_pool, "_use_token_if_there_is_one", lambda: None)
    monkeypatch.delenv(ray_pool.AUTH_MODE, raising=False)
    with pytest.raises(UserError) as raised:
        ray_pool.connect("10.0.0.1:6379")
    line = str(raised.value)
    assert "\n" not in line and line.startswith("--address 10.0.0.1:6379: ") and words in line, line
    assert "gcs_client" not in capfd.readouterr().err  # the 20 retries are not shown


@pytest.mark.parametrize("source", ["file", "RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH", None])
def test_an_explicit_address_sends_this_user_s_token_when_there_is_one(monkeypatch, tmp_path: Path,
                                                                        source: str | None) -> None:
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.delitem(sys.modules, "ray", raising=False)  # Ray reads the mode when imported
    for name in (ray_pool.AUTH_MODE, *ray_pool.TOKEN_SOURCES):
        monkeypatch.delenv(name, raising=False)
    if source == "file":
        (tmp_path / ".ray").mkdir()
        (tmp_path / ".ray" / "auth_token").write_text("secret")
    elif source is not None:
        monkeypatch.setenv(source, "secret")
    ray_pool._use_token_if_there_is_one()
    assert os.environ.get(ray_pool.AUTH_MODE) == ("token" if source else None)
    monkeypatch.setenv(ray_pool.AUTH_MODE, "disabled")  # the user's own choice stands
    ray_pool._use_token_if_there_is_one()
    assert os.environ[ray_pool.AUTH_MODE] == "disabled"


def test_a_session_joins_only_when_used_and_stops_only_what_it_started(monkeypatch) -> None:
    calls = []
    fake = SimpleNamespace(is_initialized=lambda: bool(calls), shutdown=lambda: calls.append("shutdown"),
                           init=lambda **kw: calls.append(("init", kw.get("address"))))
    monkeypatch.setattr(ray_pool, "_ray", lambda: fake)
    monkeypatch.setattr(ray_pool, "require_ray", lambda: None)
    monkeypatch.setattr(ray_pool, "_use_token_if_there_is_one", lambda: None)
    monkeypatch.setattr(ray_pool, "_join", lambda ray, address: calls.append(("init", address)))
    monkeypatch.setitem(sys.modules, "ray", fake)
    with ray_pool.ray_session("10.0.0.1:6379"):
        pass  # nothing rendered or inferred: Ray never joined
    assert calls == []
    with ray_pool.ray_session("10.0.0.1:6379"):
        assert ray_pool.join() is fake and ray_pool.join() is fake  # joined once, on first use
        assert ray_pool.connect("10.0.0.1:6379") is False  # a pool inside the run does not own it
    assert calls == [("init", "10.0.0.1:6379"), "shutdown"]


@pytest.mark.blender
def test_a_fully_cached_rerun_on_ray_never_joins_ray(tiny_copy: Path, monkeypatch) -> None:
    """9.0 s against 2.6 s: the rerun started Ray to compute nothing."""
    from sweep3d.runner.pipeline import run
    from sweep3d.stages.render.render_stage import Executor
    from tests.helpers import load_spec

    def refuse(address):
        raise AssertionError(f"joined Ray at {address!r} with nothing to compute")

    monkeypatch.setattr(ray_pool, "require_ray", lambda: None)
    monkeypatch.setattr(ray_pool, "connect", refuse)
    result = run(load_spec(tiny_copy / "spec.toml"), executor=Executor("ray", "10.0.0.1:6379"))
    assert result.failed == 0 and all(o.computed == 0 for o in result.outcomes), result.outcomes
