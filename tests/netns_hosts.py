"""Two hosts on one machine, for tests of ROS 2 across hosts: network namespaces and a veth pair.

`create_hosts` makes two network namespaces, each with its loopback up and one end of a veth
pair addressed on a private /30, and nothing else: no other interface, no route but the link's
own. A process started with `Host.command` runs inside its host with `Host.ros_environment`, so
what two processes on different hosts exchange crosses the veth link, as between two machines
on one Ethernet segment. `destroy_hosts` kills whatever still runs inside and deletes both
namespaces (which deletes the veth pair with them). Namespaces share /dev/shm, so Fast DDS's
shared memory would connect them past the link: `udp_only_profile` takes it out of a profile.

Creating network namespaces needs root (CAP_SYS_ADMIN and CAP_NET_ADMIN) and the ``ip`` tool
(Debian package ``iproute2``); where either is missing, `create_hosts` raises `NamespaceError`
with the command that failed and its error output. It installs nothing.
"""

import contextlib
from dataclasses import dataclass
import ipaddress
import json
import os
import pathlib
import re
import secrets
import shutil
import signal
import subprocess
import time
import xml.etree.ElementTree as ET

# Private addresses for the links, one /30 each (two hosts); the namespaces are isolated, so
# runs at the same time never collide even on the same /30.
LINK_NETWORK = ipaddress.IPv4Network('10.231.0.0/16')
LINK_PREFIX = 30
INTERFACE = 'veth0'  # the link's end in each namespace
COMMAND_TIMEOUT_S = 10.0
LINK_UP_TIMEOUT_S = 5.0
# ROS_AUTOMATIC_DISCOVERY_RANGE values that reach the other host (OFF disables the static peers).
DISCOVERY_RANGES = ('SUBNET', 'SYSTEM_DEFAULT', 'LOCALHOST')
NAMESPACE_NAME = re.compile(r'[A-Za-z0-9][A-Za-z0-9_.-]{0,63}')


class NamespaceError(RuntimeError):
    """An ``ip`` command creating or deleting the hosts failed; the message holds the command
    and its error output."""


@dataclass(frozen=True)
class LinkCounters:
    """Traffic through a host's end of the link since it was created [bytes, packets]."""

    rx_bytes: int
    tx_bytes: int
    rx_packets: int
    tx_packets: int


@dataclass(frozen=True)
class Host:
    """One host: a network namespace holding loopback and one end of the veth link.

    Attributes
    ----------
    namespace : str
        Name of the network namespace (``ip netns``).
    address, peer_address : str
        This host's and the other host's IPv4 address on the link.
    interface : str
        The link's interface in this namespace.
    fastdds_profile : str
        Fast DDS XML profile of the processes on this host (`udp_only_profile`); empty: the
        environment's.
    """

    namespace: str
    address: str
    peer_address: str
    interface: str = INTERFACE
    fastdds_profile: str = ''

    @property
    def network(self) -> str:
        """The link's network, e.g. ``'10.231.0.0/30'``."""
        return str(ipaddress.IPv4Interface(f'{self.address}/{LINK_PREFIX}').network)

    def ros_environment(self, discovery_range: str = 'SUBNET') -> dict[str, str]:
        """The ROS 2 environment across hosts: the other host as a static peer (unicast
        discovery), UDP only (shared memory would reach a process on the same machine without
        the network), and `fastdds_profile` if set.

        Parameters
        ----------
        discovery_range : str
            ``ROS_AUTOMATIC_DISCOVERY_RANGE``: ``'SUBNET'`` (multicast discovery on the link as
            well) or ``'SYSTEM_DEFAULT'``; ``'LOCALHOST'`` for no multicast at all, the other
            host then found through ``ROS_STATIC_PEERS`` alone.
        """
        if discovery_range not in DISCOVERY_RANGES:
            raise ValueError(f'expected discovery_range one of {DISCOVERY_RANGES}, '
                             f'got {discovery_range!r}')
        environment = {
            'ROS_AUTOMATIC_DISCOVERY_RANGE': discovery_range,
            'ROS_STATIC_PEERS': self.peer_address,
            'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4',  # when a profile uses the builtin ones
        }
        if self.fastdds_profile:
            environment['FASTRTPS_DEFAULT_PROFILES_FILE'] = self.fastdds_profile
        return environment

    def command(self, command: list[str], discovery_range: str = 'SUBNET') -> list[str]:
        """``command`` run inside this host with `ros_environment` set.

        ``ip netns exec NAMESPACE env VAR=value ... command``: both exec, so the process started
        is ``command`` itself, and the signals sent to it reach it.
        """
        if not command:
            raise ValueError('expected a command, got an empty list')
        variables = [f'{name}={value}'
                     for name, value in self.ros_environment(discovery_range).items()]
        return ['ip', 'netns', 'exec', self.namespace, 'env', *variables, *command]

    def interfaces(self) -> list[str]:
        """Names of the network interfaces in this host."""
        return [link['ifname'] for link in self._ip_json('link', 'show')]

    def routes(self) -> list[str]:
        """Destinations of the main routing table's routes (``default`` for a default route)."""
        return [route['dst'] for route in self._ip_json('route', 'show')]

    def link_counters(self) -> LinkCounters:
        """Bytes and packets through this host's end of the link so far."""
        (link,) = self._ip_json('-s', 'link', 'show', 'dev', self.interface)
        stats = link['stats64']
        return LinkCounters(rx_bytes=stats['rx']['bytes'], tx_bytes=stats['tx']['bytes'],
                            rx_packets=stats['rx']['packets'], tx_packets=stats['tx']['packets'])

    def pids(self) -> list[int]:
        """Processes running inside this host."""
        return [int(pid) for pid in _ip('netns', 'pids', self.namespace).split()]

    def _ip_json(self, *args: str) -> list[dict]:
        return json.loads(_ip('-j', '-n', self.namespace, *args) or '[]')


def link_addresses(index: int) -> tuple[str, str]:
    """The two host addresses of the ``index``-th /30 of `LINK_NETWORK`.

    Parameters
    ----------
    index : int
        0 to 16383.

    Returns
    -------
    (str, str)
        The first and the second host address, e.g. ``('10.231.0.1', '10.231.0.2')``.
    """
    links = 2 ** (LINK_PREFIX - LINK_NETWORK.prefixlen)
    if not isinstance(index, int) or not 0 <= index < links:
        raise ValueError(f'expected link index an int in [0, {links - 1}], got {index!r}')
    network = ipaddress.IPv4Network(
        (int(LINK_NETWORK.network_address) + index * 2 ** (32 - LINK_PREFIX), LINK_PREFIX))
    first, second = network.hosts()
    return str(first), str(second)


def check_namespace_name(name: str) -> str:
    """``name`` if it can name a network namespace: 1-64 of ``A-Za-z0-9_.-``, not starting with
    a dot or dash; ValueError otherwise."""
    if not isinstance(name, str) or not NAMESPACE_NAME.fullmatch(name):
        raise ValueError(f'expected namespace a name of 1-64 characters A-Za-z0-9_.- starting '
                         f'with a letter or digit, got {name!r}')
    return name


def udp_only_profile(source: str | os.PathLike, destination: str | os.PathLike,
                     ) -> pathlib.Path:
    """Write the Fast DDS XML profile ``source`` to ``destination`` without shared memory.

    Every ``SHM`` transport descriptor goes, with its entries in ``userTransports``; the rest
    (discovery timing, the UDP transports) is kept. Builtin transports are left to
    ``FASTDDS_BUILTIN_TRANSPORTS`` (`Host.ros_environment`).

    Returns
    -------
    pathlib.Path
        ``destination``.

    Raises
    ------
    ValueError
        If ``source`` is not XML, or a ``userTransports`` list would be left empty.
    """
    try:
        tree = ET.parse(source)
    except (ET.ParseError, OSError) as error:
        raise ValueError(
            f'expected source a Fast DDS XML profile, got {source}: {error}') from None
    root = tree.getroot()
    shared_memory = set()
    for descriptors in _elements(root, 'transport_descriptors'):
        for descriptor in list(descriptors):
            if _text(descriptor, 'type') == 'SHM':
                shared_memory.add(_text(descriptor, 'transport_id'))
                descriptors.remove(descriptor)
    for transports in _elements(root, 'userTransports'):
        for transport in list(transports):
            if (transport.text or '').strip() in shared_memory:
                transports.remove(transport)
        if len(transports) == 0:
            raise ValueError(f'expected source with a user transport other than shared memory, '
                             f'got only {sorted(shared_memory)} in {source}')
    if root.tag.startswith('{'):
        ET.register_namespace('', root.tag[1:].split('}')[0])  # written back as the default
    tree.write(destination, encoding='UTF-8', xml_declaration=True)
    return pathlib.Path(destination)


def _elements(root: ET.Element, name: str) -> list[ET.Element]:
    """Elements named ``name`` under ``root``, in any XML namespace."""
    return [element for element in root.iter() if element.tag.rsplit('}', 1)[-1] == name]


def _text(element: ET.Element, name: str) -> str:
    children = [child for child in element if child.tag.rsplit('}', 1)[-1] == name]
    return (children[0].text or '').strip() if children else ''


def create_hosts(prefix: str = 'inflarm-hosts', link_index: int | None = None,
                 fastdds_profile: str = '') -> tuple[Host, Host]:
    """Create two hosts joined by a veth link; raise `NamespaceError` where that fails.

    Parameters
    ----------
    prefix : str
        The namespaces are ``<prefix>-<pid>-<random>-a`` and ``-b``: unique on this machine.
    link_index : int, optional
        Which /30 of `LINK_NETWORK` the link uses (`link_addresses`); by default derived from
        the process id.
    fastdds_profile : str
        `Host.fastdds_profile` of both hosts.

    Returns
    -------
    (Host, Host)
        Host ``a`` (the first address) and host ``b``; pass them to `destroy_hosts`.
    """
    token = f'{os.getpid()}-{secrets.token_hex(3)}'
    names = [check_namespace_name(f'{prefix}-{token}-{side}') for side in 'ab']
    addresses = link_addresses(os.getpid() % 16384 if link_index is None else link_index)
    if shutil.which('ip') is None:
        raise NamespaceError('no `ip` command on PATH (Debian package iproute2)')
    a = Host(names[0], addresses[0], addresses[1], fastdds_profile=fastdds_profile)
    b = Host(names[1], addresses[1], addresses[0], fastdds_profile=fastdds_profile)
    created: list[Host] = []
    try:
        for host in (a, b):
            _ip('netns', 'add', host.namespace)
            created.append(host)
        _ip('link', 'add', a.interface, 'netns', a.namespace, 'type', 'veth',
            'peer', 'name', b.interface, 'netns', b.namespace)
        for host in (a, b):
            _ip('-n', host.namespace, 'addr', 'add', f'{host.address}/{LINK_PREFIX}',
                'dev', host.interface)
            _ip('-n', host.namespace, 'link', 'set', 'lo', 'up')
            _ip('-n', host.namespace, 'link', 'set', host.interface, 'up')
        _wait_for_link_up((a, b))
    except NamespaceError:
        destroy_hosts(created)
        raise
    return a, b


def destroy_hosts(hosts) -> None:
    """Kill every process still inside ``hosts`` (SIGKILL) and delete their namespaces.

    Tries every host; raises `NamespaceError` afterwards if a namespace could not be deleted.
    """
    failures = []
    for host in hosts:
        try:
            _kill_inside(host)
            _ip('netns', 'delete', host.namespace)
        except NamespaceError as error:
            failures.append(str(error))
    if failures:
        raise NamespaceError('; '.join(failures))


def _kill_inside(host: Host) -> None:
    deadline = time.monotonic() + COMMAND_TIMEOUT_S
    while pids := host.pids():
        for pid in pids:
            with contextlib.suppress(ProcessLookupError):  # exited meanwhile
                os.kill(pid, signal.SIGKILL)
        if time.monotonic() > deadline:
            raise NamespaceError(f'processes {pids} in {host.namespace} survive SIGKILL')
        time.sleep(0.05)


def _wait_for_link_up(hosts: tuple[Host, Host]) -> None:
    deadline = time.monotonic() + LINK_UP_TIMEOUT_S
    while True:
        states = [host._ip_json('link', 'show', 'dev', host.interface)[0]['operstate']
                  for host in hosts]
        if states == ['UP', 'UP']:
            return
        if time.monotonic() > deadline:
            raise NamespaceError(f'the veth link is not up after {LINK_UP_TIMEOUT_S} s: '
                                   f'operstate {states}')
        time.sleep(0.05)


def _ip(*args: str) -> str:
    """Run ``ip ARGS``; its output, or `NamespaceError` with the command and its stderr."""
    command = ['ip', *args]
    try:
        result = subprocess.run(command, capture_output=True, text=True,
                                timeout=COMMAND_TIMEOUT_S)
    except (OSError, subprocess.TimeoutExpired) as error:
        raise NamespaceError(f"`{' '.join(command)}` failed: {error}") from error
    if result.returncode != 0:
        raise NamespaceError(f"`{' '.join(command)}` failed (exit {result.returncode}): "
                               f'{result.stderr.strip()}')
    return result.stdout
