"""SSRF through callback_url: a job's callback never reaches loopback, private, link-local, multicast or unspecified
addresses unless the operator allows them; checked at submit (422 callback_refused) and again as it connects."""

from __future__ import annotations

import http.server
import json
import threading

import pytest

from amprep.callbacks import networks, post, resolve
from amprep.errors import AmprepError, ErrorCode
from tests.conftest import corpus
from tests.service.conftest import submit

#: what a probe reached through callback_url: the private Redis, other loopback ports, IPv6 loopback, a decimal
#: loopback, a cloud metadata service, private and unspecified addresses
REFUSED = ["http://127.0.0.1:6379/", "http://localhost:8000/x", "http://[::1]:8000/", "http://2130706433/",
           "http://0x7f000001/", "http://169.254.169.254/latest/meta-data/", "http://10.1.2.3/", "http://192.168.0.1/",
           "http://0.0.0.0:8000/", "http://[::ffff:127.0.0.1]/", "http://224.0.0.1/", "ftp://example.org/"]


@pytest.mark.parametrize("url", REFUSED)
def test_refused_addresses(url):
    with pytest.raises(AmprepError) as e:
        resolve(url)
    assert e.value.code == ErrorCode.CALLBACK_REFUSED


def test_an_operator_may_allow_a_network():
    assert [str(a) for a in resolve("http://127.0.0.1:9/", networks(["127.0.0.0/8"]))] == ["127.0.0.1"]
    with pytest.raises(AmprepError):
        networks(["not-a-network"])


class _Receiver(http.server.BaseHTTPRequestHandler):
    got: list[bytes] = []

    def do_POST(self) -> None:  # noqa: N802
        self.got.append(self.rfile.read(int(self.headers["Content-Length"])))
        self.send_response(302 if self.path == "/redirect" else 200)
        self.send_header("Location", "http://127.0.0.1:6379/")
        self.end_headers()

    def log_message(self, *args: object) -> None:
        pass


@pytest.fixture
def receiver():
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Receiver)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    _Receiver.got = []
    yield f"http://localhost:{server.server_address[1]}"
    server.shutdown()


def test_checked_again_when_sending_and_no_redirect_followed(receiver):
    """The delivery resolves and checks the host itself (a name that now resolves to loopback is refused), sends to
    the address it checked with the URL's Host header, and hands a redirect back instead of following it."""
    with pytest.raises(AmprepError) as e:
        post(receiver + "/hook", b"{}", {})
    assert e.value.code == ErrorCode.CALLBACK_REFUSED and _Receiver.got == []
    allow = networks(["127.0.0.1/32", "::1/128"])
    r = post(receiver + "/hook", b'{"a": 1}', {"Content-Type": "application/json"}, allow)
    assert r.status_code == 200 and _Receiver.got == [b'{"a": 1}']
    r = post(receiver + "/redirect", b"{}", {}, allow)
    assert r.status_code == 302 and len(_Receiver.got) == 2  # the redirect target got nothing


@pytest.mark.parametrize("url", ["http://127.0.0.1:6379/", "http://[::1]/", "http://2130706433/",
                                 "http://169.254.169.254/latest/meta-data/"])
def test_refused_at_submit_with_its_own_code(service, url):
    """An API with no allowance refuses the job before storing anything: 422 callback_refused."""
    api, proc = service.start_api(AMPREP_CALLBACK_ALLOW="")
    try:
        import httpx

        with httpx.Client(base_url=api, timeout=60) as c:
            r = submit(c, corpus("voron_vhb_din_mount.step"), params=json.dumps({"callback_url": url}))
            assert r.status_code == 422 and r.json()["code"] == "callback_refused", r.text
    finally:
        from tests.service.conftest import _stop

        _stop(proc)
