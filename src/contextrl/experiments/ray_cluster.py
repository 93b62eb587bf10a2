"""Starting or joining Ray, in one place for every caller (the ``ray`` executor, the hpo protocol): a
cluster at a given address is joined as it is; a local one is started listening on 127.0.0.1 only."""

from __future__ import annotations

import os


def start_ray(address: str | None) -> None:
    """Join the Ray cluster at ``address``, or without one start a local cluster with
    :func:`start_local_ray`: what every caller in contextrl does (the ``ray`` executor, the hpo
    protocol)."""
    import ray  # optional and slow to import: only a Ray run loads it

    if address is None:
        start_local_ray()
    else:
        ray.init(address=address, include_dashboard=False, log_to_driver=False)


def start_local_ray(**options) -> None:
    """Start a local Ray cluster for this process whose servers all listen on 127.0.0.1 only.

    Why: a private cluster on a researcher's workstation has no reason to accept connections from
    the network, and Ray's APIs (the jobs API first) execute the code they are sent
    (CVE-2023-48022). Left alone, a cluster that ``ray.init()`` starts on Linux takes the machine's
    outward address as its node address, and its GCS, raylet, object manager, agents and workers
    listen on every interface (0.0.0.0).

    How: Ray binds its servers to loopback only when the node address is 127.0.0.1 (its gRPC
    servers listen on 127.0.0.1 rather than 0.0.0.0 for such a node, as do its agents), but
    ``ray.init(_node_ip_address="127.0.0.1")`` turns 127.0.0.1 into the outward address
    (``services.resolve_ip_for_localhost``). Ray's single-machine setting does give 127.0.0.1:
    with ``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0`` (its default on macOS and Windows)
    ``services.get_node_ip_address`` returns the loopback address. It is set for the start only:
    Ray's constant for this process (read when Ray was imported) and the environment of the
    processes Ray starts now, which keep it (workers inherit the raylet's).

    As with ``ray.init()``, a cluster named by ``RAY_ADDRESS``, or one started with ``ray start`` on
    this machine, is joined instead. ``options``: further ``ray.init`` arguments (``num_cpus``...).
    """
    import ray  # optional and slow to import: only a Ray run loads it
    from ray._private import ray_constants

    variable = ray_constants.ENABLE_RAY_CLUSTERS_ENV_VAR  # RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER
    saved_variable, saved_constant = os.environ.get(variable), ray_constants.ENABLE_RAY_CLUSTER
    os.environ[variable], ray_constants.ENABLE_RAY_CLUSTER = "0", False
    try:
        ray.init(**({"include_dashboard": False, "log_to_driver": False} | options))
    finally:
        ray_constants.ENABLE_RAY_CLUSTER = saved_constant
        if saved_variable is None:
            os.environ.pop(variable, None)
        else:
            os.environ[variable] = saved_variable
