"""Certificate revocation lists on the OPC UA pair (`skin serve --trust DIR --crl FILE|DIR`, `skin loop
--opcua … --trust DIR --crl FILE|DIR`).

The public key infrastructure is made here with the ``cryptography`` package, as a shop's would be:
a certificate authority (CA) in the trust folder issues the application certificates (each with the
subject alternative name URI, key usages and extended key usage OPC UA asks for), and publishes a
revocation list (CRL) it signs. A certificate the CA revoked is refused at connection, whichever side
presents it; a list that is unreadable, expired, not yet issued, or signed by an authority outside the
trust folder is refused at start-up (exit 2, the file named) — a list that cannot be trusted would let a
revoked certificate in."""

from __future__ import annotations

import datetime as dt
import os

import pytest
from click.testing import CliRunner

from helpers import skin_server
from ncadapt import loop as lp
from ncadapt.sim import skin as sk

pytest.importorskip("asyncua")

NOW = dt.datetime.now(dt.UTC)
DAY = dt.timedelta(days=1)


def _cli(*args):
    from ncadapt.cli import main

    return CliRunner().invoke(main, [str(a) for a in args], catch_exceptions=False)


def _key():
    from cryptography.hazmat.primitives.asymmetric import rsa

    return rsa.generate_private_key(public_exponent=65537, key_size=2048)


def _name(cn):
    from cryptography import x509

    return x509.Name([x509.NameAttribute(x509.NameOID.COMMON_NAME, cn)])


def _ca(cn="shop CA"):
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes

    key = _key()
    cert = (
        x509.CertificateBuilder()
        .subject_name(_name(cn))
        .issuer_name(_name(cn))
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(NOW - DAY)
        .not_valid_after(NOW + 30 * DAY)
        .add_extension(x509.BasicConstraints(ca=True, path_length=None), critical=True)
        .add_extension(
            x509.KeyUsage(False, False, False, False, False, True, True, False, False), critical=True
        )  # key_cert_sign, crl_sign
        .sign(key, hashes.SHA256())
    )
    return key, cert


def _issue(ca, cn, uri, server: bool):
    """An application certificate for OPC UA issued by ``ca``: its URI, the key usages asyncua's
    validator asks for, client or server authentication."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes
    from cryptography.x509.oid import ExtendedKeyUsageOID

    ca_key, ca_cert = ca
    key = _key()
    cert = (
        x509.CertificateBuilder()
        .subject_name(_name(cn))
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(NOW - DAY)
        .not_valid_after(NOW + 30 * DAY)
        .add_extension(x509.SubjectAlternativeName([x509.UniformResourceIdentifier(uri)]), critical=False)
        .add_extension(x509.KeyUsage(True, True, True, True, False, False, False, False, False), critical=True)
        .add_extension(
            x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH if server else ExtendedKeyUsageOID.CLIENT_AUTH]),
            critical=False,
        )
        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False)
        .sign(ca_key, hashes.SHA256())
    )
    return key, cert


def _crl(ca, revoked, last=NOW - DAY, next_=NOW + 7 * DAY):
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes

    ca_key, ca_cert = ca
    b = x509.CertificateRevocationListBuilder().issuer_name(ca_cert.subject).last_update(last).next_update(next_)
    for cert in revoked:
        b = b.add_revoked_certificate(
            x509.RevokedCertificateBuilder().serial_number(cert.serial_number).revocation_date(last).build()
        )
    return b.sign(ca_key, hashes.SHA256())


def _save(folder, name, pair):
    from cryptography.hazmat.primitives import serialization

    key, cert = pair
    (folder / f"{name}.der").write_bytes(cert.public_bytes(serialization.Encoding.DER))
    (folder / f"{name}.pem").write_bytes(
        key.private_bytes(
            serialization.Encoding.PEM, serialization.PrivateFormat.TraditionalOpenSSL, serialization.NoEncryption()
        )
    )
    return folder / f"{name}.der", folder / f"{name}.pem"


def _der(cert):
    from cryptography.hazmat.primitives import serialization

    return cert.public_bytes(serialization.Encoding.DER)


@pytest.fixture(scope="module")
def pki(tmp_path_factory):
    """A CA; clients ``good`` and ``bad`` (revoked), controllers ``ctl`` and ``ctl_bad`` (revoked);
    the trust folder holds the CA alone; ``crl.pem`` (PEM) and ``crls/`` (one DER list) revoke the
    two bad ones."""
    from cryptography.hazmat.primitives import serialization

    d = tmp_path_factory.mktemp("pki")
    ca = _ca()
    (d / "trust").mkdir()
    (d / "trust" / "ca.der").write_bytes(_der(ca[1]))
    good = _issue(ca, "client good", lp.CLIENT_URI, server=False)
    bad = _issue(ca, "client bad", lp.CLIENT_URI, server=False)
    ctl = _issue(ca, "controller", lp.SERVER_URI, server=True)
    ctl_bad = _issue(ca, "controller revoked", lp.SERVER_URI, server=True)
    out = {"dir": d, "ca": ca, "trust": d / "trust"}
    for name, pair in (("good", good), ("bad", bad), ("ctl", ctl), ("ctl_bad", ctl_bad)):
        out[name] = _save(d, name, pair)
        out[name + "_cert"] = pair[1]
    crl = _crl(ca, [bad[1], ctl_bad[1]])
    (d / "crl.pem").write_bytes(crl.public_bytes(serialization.Encoding.PEM))
    (d / "crls").mkdir()
    (d / "crls" / "shop.crl").write_bytes(crl.public_bytes(serialization.Encoding.DER))
    out["crl"] = d / "crl.pem"
    out["crls"] = d / "crls"
    return out


def test_revocation_lists_are_read_and_checked(pki, tmp_path):
    """The lists as read: the revoked serials by issuer, from PEM and DER; a revoked certificate
    is named, the others not; a list of another CA does not revoke the same serial number."""
    for loc in (pki["crl"], pki["crls"]):
        crls = lp.revocation_lists(loc, pki["trust"])
        assert len(crls) == 1
        assert lp.revoked(pki["bad_cert"], crls) == "BadCertificateRevoked"
        assert lp.revoked(pki["ctl_bad_cert"], crls) == "BadCertificateRevoked"
        assert lp.revoked(pki["good_cert"], crls) is None
    # a list expiring after start-up: the issuer's certificates can no longer be vouched for
    crls = lp.revocation_lists(pki["crl"], pki["trust"])
    assert lp.revoked(pki["good_cert"], crls, now=NOW + 8 * DAY) == "BadCertificateRevocationUnknown"
    # another CA revoking a certificate with the good one's serial number: not the good one's issuer
    other = _ca("other CA")
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization

    fake = (
        x509.CertificateRevocationListBuilder()
        .issuer_name(other[1].subject)
        .last_update(NOW - DAY)
        .next_update(NOW + DAY)
        .add_revoked_certificate(
            x509.RevokedCertificateBuilder()
            .serial_number(pki["good_cert"].serial_number)
            .revocation_date(NOW - DAY)
            .build()
        )
        .sign(other[0], hashes.SHA256())
    )
    trust2 = tmp_path / "trust2"
    trust2.mkdir()
    (trust2 / "ca.der").write_bytes(_der(pki["ca"][1]))
    (trust2 / "other.der").write_bytes(_der(other[1]))
    (tmp_path / "other.crl").write_bytes(fake.public_bytes(serialization.Encoding.DER))
    crls = lp.revocation_lists(tmp_path / "other.crl", trust2)
    assert lp.revoked(pki["good_cert"], crls) is None


def _bad_lists(pki, tmp_path):
    """(file, the message's words) of lists refused at start-up."""
    from cryptography.hazmat.primitives import serialization

    ca = pki["ca"]
    out = []
    f = tmp_path / "expired.crl"
    f.write_bytes(_crl(ca, [], last=NOW - 10 * DAY, next_=NOW - DAY).public_bytes(serialization.Encoding.DER))
    out.append((f, "expired on"))
    f = tmp_path / "future.pem"
    f.write_bytes(_crl(ca, [], last=NOW + DAY, next_=NOW + 9 * DAY).public_bytes(serialization.Encoding.PEM))
    out.append((f, "issued in the future"))
    f = tmp_path / "garbage.crl"
    f.write_bytes(b"\x30\x82 not a list")
    out.append((f, "not a certificate revocation list"))
    f = tmp_path / "stranger.crl"
    f.write_bytes(_crl(_ca("stranger CA"), []).public_bytes(serialization.Encoding.DER))
    out.append((f, "not in the trust folder"))
    # signed by another key under the trusted CA's name: the signature does not verify
    forged = (_ca("shop CA")[0], ca[1])
    f = tmp_path / "forged.crl"
    f.write_bytes(_crl(forged, [pki["bad_cert"]]).public_bytes(serialization.Encoding.DER))
    out.append((f, "signature does not verify"))
    empty = tmp_path / "empty"
    empty.mkdir()
    out.append((empty, "no revocation list"))
    return out


@pytest.mark.parametrize("side", ["serve", "loop"])
def test_a_list_that_cannot_be_trusted_is_refused_at_start(pki, tmp_path, monkeypatch, side):
    monkeypatch.setenv("NCADAPT_OPCUA_PASSWORD", "s3cret")
    if side == "serve":
        base = ("skin", "serve", "--cert", pki["ctl"][0], "--key", pki["ctl"][1], "--user", "op")
    else:
        base = ("skin", "loop", "--opcua", "opc.tcp://127.0.0.1:1/x", "--target", sk.T_TARGET, "--depth", sk.A_G)
        base += ("--cert", pki["good"][0], "--key", pki["good"][1], "--user", "op")
    base += ("--trust", pki["trust"])
    for f, words in _bad_lists(pki, tmp_path):
        r = _cli(*base, "--crl", f, "--json", tmp_path / "x.json")
        assert r.exit_code == 2, (f, r.output)
        assert str(f) in r.output and words in r.output, r.output
        assert not (tmp_path / "x.json").exists()
    # usage: a list needs the trust folder its issuer is in; NoSecurity has no certificates
    r = _cli(*[a for a in base if a != pki["trust"] and a != "--trust"], "--crl", pki["crl"])
    assert r.exit_code == 2 and "--crl needs --trust" in r.output, r.output
    r = _cli("skin", side, *(base[2:8] if side == "loop" else ()), "--insecure", "--crl", pki["crl"])
    assert r.exit_code == 2 and "exclude each other" in r.output, r.output


def _client(pki, pair, *extra):
    return ("--cert", pki[pair][0], "--key", pki[pair][1], "--user", "op", *extra)


def test_a_revoked_client_is_refused_and_a_trusted_one_runs(pki, monkeypatch):
    """`skin serve --trust DIR --crl FILE`: the revoked client is refused at connection (exit 2 on its
    side, a line naming it and BadCertificateRevoked on the controller's), the trusted one runs both
    pockets — and checks the controller against the same CA and list (no --server-cert)."""
    url = "opc.tcp://127.0.0.1:48431/ncadapt/"
    monkeypatch.setenv("NCADAPT_OPCUA_PASSWORD", "s3cret")
    env = dict(os.environ, NCADAPT_OPCUA_PASSWORD="s3cret")
    srv = skin_server(
        "--endpoint",
        url,
        "--cert",
        pki["ctl"][0],
        "--key",
        pki["ctl"][1],
        "--user",
        "op",
        "--trust",
        pki["trust"],
        "--crl",
        pki["crls"],
        "--ack-timeout",
        120,
        env=env,
    )
    common = ("skin", "loop", "--opcua", url, "--target", sk.T_TARGET, "--depth", sk.A_G)
    try:
        first = srv.stderr.readline()
        assert "revocation lists from" in first, first
        r = _cli(*common, *_client(pki, "bad", "--server-cert", pki["ctl"][0]))
        assert r.exit_code == 2, r.output
        assert url in r.output and "revoked by its issuer's revocation list" in r.output
        line = srv.stderr.readline()
        assert "refused a client certificate 'client bad'" in line and "BadCertificateRevoked" in line, line
        r = _cli(*common, *_client(pki, "good", "--trust", pki["trust"], "--crl", pki["crl"]))
        assert r.exit_code == 0, r.output
        out, err = srv.communicate(timeout=60)
    finally:
        srv.kill()
        srv.communicate()
    assert srv.returncode == 0, err


def test_a_client_refuses_a_revoked_controller(pki, monkeypatch):
    """`skin loop --opcua … --trust DIR --crl FILE` against a controller whose certificate the CA
    revoked: refused at connection (exit 2), naming the certificate and BadCertificateRevoked."""
    url = "opc.tcp://127.0.0.1:48432/ncadapt/"
    monkeypatch.setenv("NCADAPT_OPCUA_PASSWORD", "s3cret")
    env = dict(os.environ, NCADAPT_OPCUA_PASSWORD="s3cret")
    srv = skin_server(
        "--endpoint", url, "--cert", pki["ctl_bad"][0], "--key", pki["ctl_bad"][1], "--user", "op", env=env
    )
    common = ("skin", "loop", "--opcua", url, "--target", sk.T_TARGET, "--depth", sk.A_G)
    try:
        assert srv.stderr.readline().startswith("serving")
        r = _cli(*common, *_client(pki, "good", "--trust", pki["trust"], "--crl", pki["crl"]))
        assert r.exit_code == 2, r.output
        assert url in r.output and "'controller revoked'" in r.output and "BadCertificateRevoked" in r.output
        # a trust folder of another CA: not trusted
        other = pki["dir"] / "other_trust"
        other.mkdir(exist_ok=True)
        (other / "other.der").write_bytes(_der(_ca("other CA")[1]))
        r = _cli(*common, *_client(pki, "good", "--trust", other))
        assert r.exit_code == 2 and "refused by the trust folder" in r.output, r.output
        assert "BadCertificateUntrusted" in r.output
        # without the list the same controller is trusted (issued by the CA): the list is what refuses it
        r = _cli(*common, *_client(pki, "good", "--trust", pki["trust"]), "--pockets", 1)
        assert r.exit_code == 0, r.output
    finally:
        srv.kill()
        srv.communicate()
