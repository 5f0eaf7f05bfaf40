"""What the settings' validators check with: the development secret, the patterns of a
cell name, an origin and an OPC UA endpoint, the trusted proxies' parser, loopback hosts."""

from __future__ import annotations

import ipaddress
import re

#: The secret used when none is configured.  Accepted only in the development
#: environment and only while every listener is bound to the loopback interface.
DEV_SECRET = "visioncell-development-secret-change-me"

#: A cell name: a short slug (lower-case letters and digits, inner '-' or '_', <= 40 chars).
CELL_NAME_PATTERN = re.compile(r"^[a-z0-9](?:[a-z0-9_-]{0,38}[a-z0-9])?$")


#: An origin (scheme, host, optional port; no path, no wildcard).
_ORIGIN = re.compile(
    r"^https?://[A-Za-z0-9.-]{1,253}(?::[0-9]{1,5})?$|^https?://\[[0-9A-Fa-f:.]{2,45}\](?::[0-9]{1,5})?$"
)


#: An OPC UA endpoint: opc.tcp://HOST:PORT with an optional path.
_OPCUA_ENDPOINT = re.compile(
    r"^opc\.tcp://(?P<host>[A-Za-z0-9.-]{1,253}|\[[0-9A-Fa-f:.]{2,45}\]):(?P<port>[0-9]{1,5})"
    r"(?P<path>/[A-Za-z0-9._~/-]{0,128})?$"
)

#: Most entries of ``VISIONCELL_TRUSTED_PROXIES``.
MAX_TRUSTED_PROXIES = 32

Network = ipaddress.IPv4Network | ipaddress.IPv6Network


def parse_trusted_proxies(value: str) -> tuple[Network, ...]:
    """The networks of a comma-separated list of IP addresses and CIDR networks.

    ``ValueError`` naming ``VISIONCELL_TRUSTED_PROXIES`` and the bad entry for anything else
    (a host name, a wildcard, more than :data:`MAX_TRUSTED_PROXIES` entries).
    """
    if not isinstance(value, str):
        raise ValueError(f"VISIONCELL_TRUSTED_PROXIES must be text, got {value!r}")
    if len(value) > 64 * MAX_TRUSTED_PROXIES:
        raise ValueError(
            f"VISIONCELL_TRUSTED_PROXIES is too long ({len(value)} characters): list at most "
            f"{MAX_TRUSTED_PROXIES} addresses or networks"
        )
    entries = [e.strip() for e in value.split(",") if e.strip()]
    if len(entries) > MAX_TRUSTED_PROXIES:
        raise ValueError(
            f"VISIONCELL_TRUSTED_PROXIES lists {len(entries)} entries; at most "
            f"{MAX_TRUSTED_PROXIES} are accepted"
        )
    networks = []
    for entry in entries:
        try:
            networks.append(ipaddress.ip_network(entry, strict=False))
        except ValueError:
            raise ValueError(
                "VISIONCELL_TRUSTED_PROXIES must be a comma-separated list of IP addresses "
                f"or networks (e.g. '10.0.0.5, 192.168.1.0/24'), got {entry[:80]!r}"
            ) from None
    return tuple(networks)


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False
