"""A local Ray that contextrl starts (the ``ray`` executor without ``--address``, the hpo protocol)
listens on the loopback address only: no server of its processes accepts connections from the
network (see ``ray_cluster.start_local_ray``)."""

import ipaddress
import os
import time

import psutil
import pytest

from contextrl.experiments.ray_cluster import start_ray

pytestmark = pytest.mark.usefixtures("shut_down_ray")  # conftest.py


def _listening(process: psutil.Process) -> set[tuple[str, int]]:
    """The (address, port) of each TCP socket ``process`` listens on (none once it has gone)."""
    try:
        return {
            (connection.laddr.ip, connection.laddr.port)
            for connection in process.net_connections(kind="tcp")
            if connection.status == psutil.CONN_LISTEN
        }
    except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
        return set()


def _is_loopback(host: str) -> bool:
    address = ipaddress.ip_address(host.split("%")[0])
    if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
        address = address.ipv4_mapped
    return address.is_loopback  # 127.0.0.0/8 or ::1; never 0.0.0.0, :: or an outward address


def _ray_listeners(driver_before: set[tuple[str, int]]) -> dict[tuple[str, int], str]:
    """What Ray's processes listen on: every process this one started (gcs_server, raylet, the
    agents, the workers), and this process's own new sockets (the driver's core worker)."""
    found = {}
    for child in psutil.Process().children(recursive=True):
        try:
            words = [os.path.basename(word) for word in child.cmdline() if word[:1] != "-"]
        except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
            continue
        words = words or [child.name()]
        name = (
            " ".join(words[:2]) if words[0].startswith("python") else words[0]
        )  # python monitor.py
        for socket in _listening(child):
            found[socket] = f"{name} (pid {child.pid})"
    for socket in _listening(psutil.Process()) - driver_before:
        found[socket] = f"this process, the driver (pid {os.getpid()})"
    return found


def test_a_local_ray_listens_on_the_loopback_address_only():
    import ray

    if ray.is_initialized():  # a Ray left over by another file on this worker
        ray.shutdown()
    driver_before = _listening(psutil.Process())
    start_ray(None)  # exactly what the executors and the hpo protocol call without --address

    @ray.remote(num_cpus=0)
    def worker_pid() -> int:
        return os.getpid()

    # A task, so a worker process runs (and listens) too; Ray's agents may bind a moment after
    # ray.init returns, so the sockets are gathered over a few seconds.
    assert ray.get(worker_pid.remote(), timeout=60) != os.getpid()
    node_address = ray.util.get_node_ip_address()
    listeners: dict[tuple[str, int], str] = {}
    for _ in range(4):
        listeners |= _ray_listeners(driver_before)
        time.sleep(0.5)
    ray.shutdown()

    outside = {
        f"{host}:{port}": who for (host, port), who in listeners.items() if not _is_loopback(host)
    }
    assert listeners, "no Ray process was found listening: the check would pass vacuously"
    assert any("gcs_server" in who for who in listeners.values()), listeners
    assert not outside, f"Ray servers reachable from the network: {outside}"
    assert node_address == "127.0.0.1", node_address  # the address Ray gives its nodes' peers
