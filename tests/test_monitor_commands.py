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


def _requests(session, *calls, **settings):
    """Run `calls(client)` coroutines against the monitor's app (commands on, `settings` more [monitor] keys);
    returns their results."""
    async def run():
        app = make_app(session, RIG, MonitorSection(commands=True, **settings))
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


def test_a_name_the_monitor_is_not_served_under_is_refused(session):
    """DNS rebinding: a browser at an allowed address (here 127.0.0.1) opened http://evil.example:port/ after the
    attacker pointed that name at this computer; it names the attacker's host in both Host and Origin, which match."""
    session, received = session

    async def get(client, host):
        r = await client.get("/", headers={"Host": host})
        return r.status, await r.text()

    async def post(client, host):
        r = await client.post("/cmd/rotate_scene", data='{"deg": 90}', headers={
            "Host": host, "Origin": f"http://{host}", "Content-Type": "application/json"})
        return r.status, await r.text()

    async def websocket(client, host):
        r = await client.get("/ws", headers={"Host": host, "Origin": f"http://{host}", "Connection": "Upgrade",
                                             "Upgrade": "websocket", "Sec-WebSocket-Version": "13",
                                             "Sec-WebSocket-Key": "dGhlIHNhbXBsZSBub25jZQ=="})
        return r.status, await r.text()

    page, command, ws, local, by_address, by_v6 = _requests(
        session, lambda c: get(c, f"evil.example:{c.port}"), lambda c: post(c, f"evil.example:{c.port}"),
        lambda c: websocket(c, f"evil.example:{c.port}"), lambda c: post(c, f"localhost:{c.port}"),
        lambda c: post(c, f"192.0.2.7:{c.port}"), lambda c: get(c, f"[::1]:{c.port}"))
    for status, text in (page, command, ws):
        assert status == 403 and text.startswith(
            "antarium monitor: the name 'evil.example' (Host header) is not one this monitor is served under; open "
            "it by this computer's address or one of: "), (status, text)
        assert "localhost" in text
    assert local[0] == by_address[0] == by_v6[0] == 200, (local, by_address, by_v6)
    assert received == ['{"deg": 90}', '{"deg": 90}']  # only by its own names and addresses


def test_a_name_set_in_monitor_hosts_is_served(session):
    """A DNS alias of the rig computer, named in [monitor] hosts, opens the page; other names are still refused."""
    session, received = session

    async def post(client, host):
        r = await client.post("/cmd/rotate_scene", data='{"deg": 45}', headers={
            "Host": host, "Origin": f"http://{host}", "Content-Type": "application/json"})
        return r.status

    alias, evil = _requests(session, lambda c: post(c, f"Dome-PC.lab.example:{c.port}"),
                            lambda c: post(c, f"evil.example:{c.port}"), hosts=["dome-pc.lab.example"])
    assert (alias, evil) == (200, 403)
    assert received == ['{"deg": 45}']


def test_the_page_may_send_only_the_parameters_its_commands_declare(session):
    """trial_start's `folder` (where on the rig the log is written) is for the bus, not for a page."""
    session, received = session

    async def post(client, name, body):
        r = await client.post(f"/cmd/{name}", data=json.dumps(body), headers={"Content-Type": "application/json"})
        return r.status, await r.json()

    folder, extra, ok = _requests(
        session, lambda c: post(c, "trial_start", {"name": "t1", "folder": "/tmp/elsewhere"}),
        lambda c: post(c, "trial_stop", {"all": True}),
        lambda c: post(c, "trial_start", {"name": "t1", "metadata": {"from": "page"}}))
    assert folder == (400, {"error": "trial_start: 'folder' cannot be sent from the page; allowed: name, metadata "
                                     "(use the bus for the others)"})
    assert extra == (400, {"error": "trial_stop: 'all' cannot be sent from the page; allowed: no parameters (use "
                                    "the bus for the others)"})
    assert ok[0] == 200
    assert received == ['{"name": "t1", "metadata": {"from": "page"}}']
