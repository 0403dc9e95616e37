"""The secured fleet config: user/password, an ACL per robot, TLS and mTLS.

Real Zenoh sessions on 127.0.0.1; certificates are generated at test time."""

from __future__ import annotations

import datetime
import json
import socket
import time

import pytest

from agents.fleet import client_config, router_config
from agents.session import Bus, SessionSpec, open_session
from polyswarm.errors import CommsError
from protocols.chunks import MapChunk, MapKind
from protocols.keys import SwarmKeys

KEYS = SwarmKeys("lab")


def port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def write(tmp_path, name: str, conf: dict) -> str:
    p = tmp_path / name
    p.write_text(json.dumps(conf))
    return str(p)


def received(bus: Bus, wait_s: float = 1.5) -> list:
    got, end = [], time.monotonic() + wait_s
    while time.monotonic() < end:
        got += bus.poll(timeout_s=0.05)
    return got


@pytest.fixture
def users(tmp_path) -> str:
    p = tmp_path / "users.txt"
    p.write_text("r1:secret-r1\nr2:secret-r2\n")
    return str(p)


def test_a_robot_publishes_only_under_its_own_prefix(tmp_path, users):
    ep = f"tcp/127.0.0.1:{port()}"
    rconf = write(tmp_path, "router.json5", router_config("lab", ["r1", "r2"], ep, users))
    with open_session(SessionSpec.router(ep, rconf)) as rs:
        coord = Bus(rs, "coordinator")
        coord.subscribe(KEYS.all_robots("map/delta"), MapChunk)
        cconf = write(tmp_path, "r1.json5", client_config(ep, "r1", "secret-r1"))
        with open_session(SessionSpec.client(ep, cconf), connect_timeout_s=5) as cs:
            r1 = Bus(cs, "r1")
            time.sleep(0.5)
            r1.publish_map(KEYS.robot("r1").map_delta, MapKind.DELTA, b"own", 0, 1, 1.0)
            r1.publish_map(KEYS.robot("r2").map_delta, MapKind.DELTA, b"forged", 0, 1, 1.0)
            got = received(coord)
            r1.close()
        coord.close()
    assert [g.payload for g in got] == [b"own"]
    assert KEYS.robot_of(got[0].key) == "r1"


def test_wrong_password_cannot_connect(tmp_path, users):
    ep = f"tcp/127.0.0.1:{port()}"
    rconf = write(tmp_path, "router.json5", router_config("lab", ["r1"], ep, users))
    with open_session(SessionSpec.router(ep, rconf)):
        bad = write(tmp_path, "bad.json5", client_config(ep, "r1", "guess"))
        with pytest.raises(CommsError), open_session(SessionSpec.client(ep, bad), 1.0):
            pass
        nobody = write(tmp_path, "nobody.json5", client_config(ep, "r9", "secret-r1"))
        with pytest.raises(CommsError), open_session(SessionSpec.client(ep, nobody), 1.0):
            pass


# --- TLS -------------------------------------------------------------------------------------


def _ca(name: str):
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import NameOID

    key = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)])
    now = datetime.datetime.now(datetime.UTC)
    cert = (
        x509.CertificateBuilder()
        .subject_name(subject)
        .issuer_name(subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(days=1))
        .not_valid_after(now + datetime.timedelta(days=30))
        .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
        .sign(key, hashes.SHA256())
    )
    return key, cert


def _leaf(ca, name: str):
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    ca_key, ca_cert = ca
    key = ec.generate_private_key(ec.SECP256R1())
    now = datetime.datetime.now(datetime.UTC)
    cert = (
        x509.CertificateBuilder()
        .subject_name(x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, name)]))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(now - datetime.timedelta(days=1))
        .not_valid_after(now + datetime.timedelta(days=30))
        .add_extension(x509.SubjectAlternativeName([x509.DNSName("localhost")]), critical=False)
        .add_extension(
            x509.ExtendedKeyUsage(
                [ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]
            ),
            critical=False,
        )
        .sign(ca_key, hashes.SHA256())
    )
    return key, cert


def _pem(tmp_path, name: str, key, cert) -> tuple[str, str]:
    from cryptography.hazmat.primitives import serialization

    kp, cp = tmp_path / f"{name}-key.pem", tmp_path / f"{name}.pem"
    kp.write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM,
            serialization.PrivateFormat.PKCS8,
            serialization.NoEncryption(),
        )
    )
    cp.write_bytes(cert.public_bytes(serialization.Encoding.PEM))
    return str(kp), str(cp)


def test_mtls_admits_a_certificate_of_the_fleet_ca_only(tmp_path, users):
    ca, other_ca = _ca("polyswarm fleet CA"), _ca("someone else")
    ca_file = _pem(tmp_path, "ca", *ca)[1]
    rkey, rcert = _pem(tmp_path, "router", *_leaf(ca, "router"))
    good_key, good_cert = _pem(tmp_path, "r1", *_leaf(ca, "r1"))
    bad_key, bad_cert = _pem(tmp_path, "intruder", *_leaf(other_ca, "r1"))
    ep = f"tls/localhost:{port()}"
    tls = {
        "root_ca_certificate": ca_file,
        "listen_certificate": rcert,
        "listen_private_key": rkey,
        "enable_mtls": True,
    }
    rconf = write(tmp_path, "router.json5", router_config("lab", ["r1"], ep, users, tls))

    def client(key, cert) -> str:
        ctls = {
            "root_ca_certificate": ca_file,
            "connect_certificate": cert,
            "connect_private_key": key,
            "enable_mtls": True,
        }
        return write(tmp_path, f"c-{port()}.json5", client_config(ep, "r1", "secret-r1", ctls))

    with open_session(SessionSpec.router(ep, rconf)) as rs:
        coord = Bus(rs, "coordinator")
        coord.subscribe(KEYS.all_robots("map/delta"), MapChunk)
        with open_session(SessionSpec.client(ep, client(good_key, good_cert)), 5.0) as cs:
            r1 = Bus(cs, "r1")
            time.sleep(0.5)
            r1.publish_map(KEYS.robot("r1").map_delta, MapKind.DELTA, b"over tls", 0, 1, 1.0)
            assert [g.payload for g in received(coord)] == [b"over tls"]
            r1.close()
        with (
            pytest.raises(CommsError),
            open_session(SessionSpec.client(ep, client(bad_key, bad_cert)), 1.0),
        ):
            pass
        coord.close()
