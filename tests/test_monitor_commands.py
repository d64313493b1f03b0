"""Page commands reach the rig only from the monitor's own page: a page of another site, open in a browser the rig
allows, is refused (its origin), and so is a command that is not JSON (which a foreign page could post without a
CORS check); the websocket too. Exercised over HTTP with aiohttp's test client against the monitor's application
on a real zenoh session; the rig's command queryable is a stand-in that answers as the server does."""

from __future__ import annotations

import asyncio
import json

import pytest

pytest.importorskip("aiohttp")
from aiohttp.test_utils import TestClient, TestServer  # noqa: E402

from antarium import bus  # noqa: E402
from antarium.config import MonitorSection  # noqa: E402
from antarium.monitor.app import make_app  # noqa: E402

RIG = "tcmd"


@pytest.fixture
def session():
    s = bus.open_session({"listen": [bus.free_tcp_endpoint()]}, role="server")
    received = []

    def answer(query):
        received.append(query.payload.to_bytes().decode())
        query.reply(query.key_expr, json.dumps({"ok": True, "result": None}))

    queryable = s.declare_queryable(bus.rig_key(RIG, "cmd", "*"), answer)
    yield s, received
    queryable.undeclare()
    s.close()


def _requests(session, *calls):
    """Run `calls(client)` coroutines against the monitor's app (commands on); returns their results."""
    async def run():
        app = make_app(session, RIG, MonitorSection(commands=True))
        async with TestClient(TestServer(app)) as client:
            return [await call(client) for call in calls]
    return asyncio.run(run())


async def _post(client, headers, body='{"deg": 90}'):
    r = await client.post("/cmd/rotate_scene", data=body, headers=headers)
    return r.status, await r.json()


def test_only_the_monitors_own_page_may_send_commands(session):
    session, received = session

    def own(client):
        return f"http://{client.host}:{client.port}"

    json_type = {"Content-Type": "application/json"}
    results = _requests(
        session,
        lambda c: _post(c, {**json_type, "Origin": "http://elsewhere.example"}),
        lambda c: _post(c, {"Content-Type": "text/plain", "Origin": own(c)}),
        lambda c: _post(c, {}),
        lambda c: _post(c, {**json_type, "Origin": own(c)}),
        lambda c: _post(c, json_type),  # a script on the lab network (no browser, no origin) may
    )
    foreign, plain, untyped, page, script = results
    assert foreign[0] == 403 and foreign[1]["error"].startswith(
        "rotate_scene: a page from http://elsewhere.example may not use the monitor; only its own page (http://")
    assert plain[0] == untyped[0] == 415
    assert plain[1]["error"] == ("rotate_scene: commands are sent as JSON (Content-Type: application/json), got "
                                 "'text/plain'")
    assert page == script == (200, {"ok": True, "result": None})
    assert received == ['{"deg": 90}', '{"deg": 90}']  # only the two accepted reached the rig


def test_a_page_of_another_site_gets_no_websocket(session):
    session, _ = session

    async def connect(client, origin):
        r = await client.get("/ws", headers={"Origin": origin, "Connection": "Upgrade", "Upgrade": "websocket",
                                             "Sec-WebSocket-Version": "13",
                                             "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="})
        return r.status, await r.text()

    foreign, own = _requests(session, lambda c: connect(c, "http://elsewhere.example"),
                             lambda c: connect(c, f"http://{c.host}:{c.port}"))
    assert foreign[0] == 403 and "a page from http://elsewhere.example may not use the monitor" in foreign[1]
    assert own[0] == 101
