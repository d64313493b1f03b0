"""The spec's port 19055 against the embedded default's OS-chosen port: said in the docs, printed by serve."""

from pathlib import Path
from types import SimpleNamespace

from antarium.commands.serve import link_line
from antarium.config import load_config, resolve
from antarium.firmware_proto.link import open_link


def _served(link, emulator, port: int) -> SimpleNamespace:
    """What `link_line` reads of a server: its link, its spawned emulator (or None), its config's [link] port."""
    return SimpleNamespace(link=link, emulator=emulator, config=resolve({"link": {"port": port}}))


def test_serve_prints_the_udp_port_in_use_and_says_it_was_chosen():
    link = open_link("udp", host="127.0.0.1", port=45123)
    try:
        line = link_line(_served(link, object(), 0))
    finally:
        link.close()
    assert "udp 127.0.0.1:45123" in line and "OS-chosen port" in line and "19055" in line
    assert "OS-chosen" not in link_line(_served(SimpleNamespace(address=("10.0.0.2", 19055)), None, 19055))


def test_a_spawned_emulator_on_a_configured_port_is_not_said_to_be_os_chosen():
    line = link_line(_served(SimpleNamespace(address=("127.0.0.1", 19055)), object(), 19055))
    assert line == "antarium serve: dome link: udp 127.0.0.1:19055 (spawned emulator, [link] port)"


def test_the_docs_say_the_embedded_default_does_not_use_19055():
    assert load_config(None).link.port == 0
    text = (Path(__file__).parents[1] / "docs" / "protocol.md").read_text()
    assert "The embedded default\n  rig does **not** use 19055" in text
