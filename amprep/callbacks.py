"""Where a job's callback may go, and its delivery: never to a loopback, link-local, private, shared, multicast,
reserved or unspecified address (the service's own Redis, a cloud's metadata service, the LAN) unless the operator
lists it in AMPREP_CALLBACK_ALLOW. The host is resolved and checked when the job is submitted and again when the
callback is sent, and the connection goes to the address that was checked (a DNS answer that changes in between
cannot slip through); redirects are not followed."""

from __future__ import annotations

import ipaddress
import socket
from collections.abc import Sequence
from urllib.parse import urlsplit, urlunsplit

import httpx

from amprep.errors import AmprepError, ErrorCode

Network = ipaddress.IPv4Network | ipaddress.IPv6Network
Address = ipaddress.IPv4Address | ipaddress.IPv6Address


def networks(entries: Sequence[str]) -> list[Network]:
    """The allowed networks of AMPREP_CALLBACK_ALLOW entries ('127.0.0.1', '10.0.0.0/8', '::1'); invalid_parameter
    for an entry that is not an address or network."""
    out = []
    for e in entries:
        try:
            out.append(ipaddress.ip_network(e.strip(), strict=False))
        except ValueError:
            raise AmprepError(ErrorCode.INVALID_PARAMETER, f"AMPREP_CALLBACK_ALLOW: '{e}' is not an address or "
                              "network") from None
    return out


def _refused(url: str, why: str) -> AmprepError:
    return AmprepError(ErrorCode.CALLBACK_REFUSED, f"callback_url {url}: {why}")


def _public(ip: Address) -> bool:
    mapped = getattr(ip, "ipv4_mapped", None)
    ip = mapped or ip
    return ip.is_global and not ip.is_multicast


def resolve(url: str, allow: Sequence[Network] = ()) -> list[Address]:
    """The addresses `url`'s host resolves to, each public or allowed; callback_refused when the scheme is not
    http(s), the host does not resolve, or any address it resolves to is neither."""
    parts = urlsplit(url)
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise _refused(url, "only http and https URLs with a host are accepted")
    try:
        port = parts.port or (443 if parts.scheme == "https" else 80)
        infos = socket.getaddrinfo(parts.hostname, port, type=socket.SOCK_STREAM)
    except (OSError, ValueError, UnicodeError) as exc:
        raise _refused(url, f"the host does not resolve ({exc})") from None
    ips = list(dict.fromkeys(ipaddress.ip_address(info[4][0].split("%")[0]) for info in infos))
    for ip in ips:
        if not (_public(ip) or any(ip in net for net in allow)):
            raise _refused(url, f"the host resolves to {ip}, a loopback, private, link-local or reserved address "
                           "(the operator may allow it in AMPREP_CALLBACK_ALLOW)")
    return ips


def post(url: str, body: bytes, headers: dict[str, str], allow: Sequence[Network] = (),
         timeout: float = 10.0) -> httpx.Response:
    """POST `body` to `url` at an address resolve() checked just now, with the URL's Host header and TLS server name;
    no redirect is followed. callback_refused when the address is not allowed; httpx's errors otherwise."""
    parts = urlsplit(url)
    ip = resolve(url, allow)[0]
    host = f"[{ip}]" if ip.version == 6 else str(ip)
    netloc = f"{host}:{parts.port}" if parts.port else host
    pinned = urlunsplit((parts.scheme, netloc, parts.path or "/", parts.query, ""))
    host_header = parts.netloc.rsplit("@", 1)[-1]
    with httpx.Client(timeout=timeout, follow_redirects=False) as client:
        request = client.build_request("POST", pinned, content=body, headers={**headers, "Host": host_header},
                                       extensions={"sni_hostname": parts.hostname})
        return client.send(request)
