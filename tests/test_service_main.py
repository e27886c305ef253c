"""The services' one ``main()`` skeleton (runtime.service_main), over real Zenoh sessions on loopback: a node
that does not open is one error line and exit 1, with what was made before it released; a node that opened is
closed (its liveliness token gone) whether the service's body returns or raises."""

from __future__ import annotations

import pytest

from runtime.config import ZenohSettings
from runtime.service_main import refuse, serve
from runtime.session import ServiceNode

from .zenoh_helpers import free_port, wait_alive, wait_gone


def _settings(port: int, listen: bool) -> ZenohSettings:
    end = (f"tcp/127.0.0.1:{port}",)
    return ZenohSettings(listen=end, robot_id=f"t{port}") if listen else ZenohSettings(connect=end,
                                                                                        robot_id=f"t{port}")


def test_a_node_that_cannot_open_is_one_error_line_and_exit_1_with_the_service_released(capsys):
    port = free_port()
    released = []
    with ServiceNode("holder", _settings(port, listen=True)):  # the endpoint is busy
        code = serve("lamps sim", "sim", _settings(port, listen=True), lambda node: 0,
                     on_open_failure=lambda: released.append(True))
    err = capsys.readouterr().err
    assert code == 1 and released == [True]
    assert err.startswith("lamps sim: error: cannot open the Zenoh session (") and err.count("\n") == 1, err


@pytest.mark.parametrize("raises", [False, True])
def test_the_node_is_closed_when_the_body_returns_or_raises(raises):
    port = free_port()
    with ServiceNode("watcher", _settings(port, listen=True)) as watcher:
        def body(node: ServiceNode) -> int:
            wait_alive(watcher, "robot")  # the service's node is open while its body runs
            if raises:
                raise RuntimeError("the body failed")
            return 3

        if raises:
            with pytest.raises(RuntimeError, match="the body failed"):
                serve("lamps robot", "robot", _settings(port, listen=False), body)
        else:
            assert serve("lamps robot", "robot", _settings(port, listen=False), body) == 3
        wait_gone(watcher, "robot")


def test_refuse_says_the_program_and_the_problem(capsys):
    assert refuse("lamps perception", ValueError("--fit-inks needs --masks FILE")) == 1
    assert capsys.readouterr().err == "lamps perception: error: --fit-inks needs --masks FILE\n"


@pytest.mark.parametrize("service", ["robot", "perception"])
def test_a_service_whose_endpoint_is_busy_exits_1_naming_it(service, capsys, monkeypatch):
    """``lamps robot`` and ``lamps perception`` through their ``main()``: the port another session holds."""
    import importlib

    monkeypatch.setenv("LAMPS_NICE", "keep")  # in this process: the test worker's priority stays as it is
    port = free_port()
    main = importlib.import_module(f"{service}.cli").main
    extra = ["--backend", "mock"] if service == "robot" else []
    with ServiceNode("holder", _settings(port, listen=True)):
        code = main([*extra, "--listen", f"tcp/127.0.0.1:{port}", "--robot-id", f"t{port}"])
    err = capsys.readouterr().err
    assert code == 1 and f"lamps {service}: error: cannot open the Zenoh session (" in err, err
