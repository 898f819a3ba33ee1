"""The real-time loop: thickness readings in, W1 offsets out.

:func:`run` reads thickness samples from a *source*, steps a compensator on δ = T − T_g and
writes its ``w1_offset`` to a *sink*. Adapters:

- in-process: :class:`MachineLink` wraps the virtual machine of :mod:`ncadapt.sim.skin`;
- CSV replay: :class:`CsvSource` (a recorded ``thickness`` column) and :class:`CsvSink`;
- OPC UA (asyncua): :func:`run_opcua` — the compensator as an OPC UA client that reads a thickness
  variable and writes a W1-offset variable on the controller's server; :func:`serve_machine`
  plays such a controller with the virtual machine (for tests and demonstrations).

OPC UA exchange (namespace ``urn:ncadapt:skin``, object ``Controller``): the controller publishes
``Thickness`` (mm; NaN when the gauge's limit filter rejected the reading) and then increments
``Sequence``; the client answers each sequence number by writing ``W1Offset`` (mm; only when it
stepped) and then ``Ack`` = that number. The controller applies the offset and cuts on to the
next reading only after the Ack, so a run over OPC UA is step for step the in-process run.
Security: Basic256Sha256 with SignAndEncrypt, application certificates and a user name and
password (:class:`Security`); NoSecurity only when asked for (``--insecure``). The
controller also publishes ``Pockets`` (how many it will finish); the client sets ``Fault`` = true
when its interlocks stop the loop, and the controller then holds W1 and stops feeding.

Every adapter runs the same interlocks (:class:`ncadapt.processes.skin.Interlocks`) between the
readings and the compensator.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from dataclasses import dataclass

NAMESPACE = "urn:ncadapt:skin"
SERVER_URI = "urn:ncadapt:skin:controller"
CLIENT_URI = "urn:ncadapt:skin:client"


@dataclass(frozen=True)
class Security:
    """OPC UA security of the exchange: Basic256Sha256 with SignAndEncrypt, an application
    certificate (DER) and private key (PEM) per side, and a user name and password. The client also
    names the controller's certificate (``peer_cert``: a controller presenting another one is
    refused); the controller accepts ``user`` with ``password`` only and, with ``trust`` (a folder
    of DER or PEM certificates), only the client certificates in it or issued by one in it. On the
    client, ``trust`` checks the controller's certificate the same way (with or instead of
    ``peer_cert``). ``crl`` (a file or a folder of certificate revocation lists, PEM or DER, with
    ``trust``): a peer certificate revoked by a list of its issuer is refused
    (:func:`revocation_lists`). None instead of a Security is NoSecurity (``--insecure``)."""

    cert: str
    key: str
    user: str
    password: str
    peer_cert: str | None = None
    trust: str | None = None
    crl: str | None = None


async def make_certificates(folder, host: str = "127.0.0.1") -> dict:
    """Self-signed application certificates (one year) for the controller and the client, as
    asyncua makes them: ``controller.der``/``controller.pem``, ``client.der``/``client.pem`` in
    ``folder``; an existing valid pair is kept. Returns the paths."""
    from pathlib import Path

    from asyncua.crypto.cert_gen import setup_self_signed_certificate
    from cryptography.x509.oid import ExtendedKeyUsageOID

    folder = Path(folder)
    out = {}
    for name, uri, use in (
        ("controller", SERVER_URI, ExtendedKeyUsageOID.SERVER_AUTH),
        ("client", CLIENT_URI, ExtendedKeyUsageOID.CLIENT_AUTH),
    ):
        key, cert = folder / f"{name}.pem", folder / f"{name}.der"
        await setup_self_signed_certificate(key, cert, uri, host, [use], {"commonName": f"ncadapt skin {name}"})
        key.chmod(0o600)  # a private key: its owner's only
        out[name] = (str(cert), str(key))
    return out


def trusted_certificates(folder) -> list:
    """The certificate files of a trust folder (``*.der``, ``*.pem``, as asyncua's TrustStore loads
    them), sorted; :class:`ncadapt.errors.InputError` when there is none, or one is no certificate."""
    from pathlib import Path

    from cryptography import x509

    from .errors import InputError

    folder = Path(folder)
    files = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in (".der", ".pem"))
    if not files:
        raise InputError(
            "no certificate (*.der, *.pem) in the trust folder: every client would be refused", str(folder)
        )
    for p in files:
        data = p.read_bytes()
        try:
            x509.load_pem_x509_certificate(data) if p.suffix.lower() == ".pem" else x509.load_der_x509_certificate(data)
        except ValueError:
            raise InputError("not a certificate (a private key does not belong in a trust folder)", str(p)) from None
    return files


# the suffixes of revocation lists read from a --crl folder
CRL_SUFFIXES = (".crl", ".pem", ".der")


def _load_crl(path):
    from cryptography import x509

    data = path.read_bytes()
    if data.lstrip().startswith(b"-----BEGIN"):
        return x509.load_pem_x509_crl(data)
    return x509.load_der_x509_crl(data)


def revocation_lists(location, trust, now=None) -> list:
    """The certificate revocation lists of ``location`` (a CRL file, or a folder of ``*.crl``,
    ``*.pem``, ``*.der``; each PEM or DER), checked for use: each must be readable, signed by a
    certificate of the ``trust`` folder whose subject is the list's issuer (its signature verified
    with that certificate's key), already issued (``last_update`` ≤ now) and not expired (its
    ``next_update`` — when its issuer publishes the next one — not past). Returns the lists
    ``[(path, CertificateRevocationList)]``; anything else is :class:`ncadapt.errors.InputError`
    located at the file (a list that cannot be trusted would let a revoked certificate in).

    asyncua's own TrustStore matches revoked serial numbers of any list against any certificate,
    whoever issued either, and never looks at the dates: these checks are ncadapt's."""
    from datetime import UTC, datetime
    from pathlib import Path

    from cryptography import x509

    from .errors import InputError

    now = datetime.now(UTC) if now is None else now
    location = Path(location)
    if location.is_dir():
        files = sorted(p for p in location.iterdir() if p.is_file() and p.suffix.lower() in CRL_SUFFIXES)
        if not files:
            raise InputError(
                f"no revocation list ({', '.join('*' + x for x in CRL_SUFFIXES)}) in the folder", str(location)
            )
    else:
        files = [location]
    issuers = []
    for p in trusted_certificates(trust):
        data = p.read_bytes()
        issuers.append(
            x509.load_pem_x509_certificate(data) if p.suffix.lower() == ".pem" else x509.load_der_x509_certificate(data)
        )
    out = []
    for p in files:
        try:
            crl = _load_crl(p)
        except (ValueError, OSError) as e:
            raise InputError(f"not a certificate revocation list (PEM or DER): {e}", str(p)) from None
        signers = [c for c in issuers if c.subject == crl.issuer]
        if not signers:
            raise InputError(
                f"the revocation list is issued by {crl.issuer.rfc4514_string()!r}, which is not in the trust "
                f"folder {trust}: its signature cannot be checked",
                str(p),
            )
        if not any(_signed_by(crl, c) for c in signers):
            raise InputError(
                f"the revocation list's signature does not verify with {crl.issuer.rfc4514_string()!r} of the "
                "trust folder: refused",
                str(p),
            )
        if crl.last_update_utc > now:
            raise InputError(
                f"the revocation list is issued in the future ({crl.last_update_utc:%Y-%m-%d %H:%M} UTC)", str(p)
            )
        if crl.next_update_utc is None or crl.next_update_utc < now:
            when = (
                "has no next update date"
                if crl.next_update_utc is None
                else f"expired on {crl.next_update_utc:%Y-%m-%d %H:%M} UTC"
            )
            raise InputError(
                f"the revocation list {when}: get the current one from its issuer {crl.issuer.rfc4514_string()!r}",
                str(p),
            )
        out.append((str(p), crl))
    return out


def _signed_by(crl, cert) -> bool:
    try:
        return bool(crl.is_signature_valid(cert.public_key()))
    except (TypeError, ValueError):
        return False


def revoked(cert, crls, now=None) -> str | None:
    """Why ``cert`` may not be used under the lists ``crls`` (:func:`revocation_lists`): the
    status name ``BadCertificateRevoked`` when a list of its issuer names its serial number,
    ``BadCertificateRevocationUnknown`` when a list of its issuer has expired since it was read;
    None when it may."""
    from datetime import UTC, datetime

    now = datetime.now(UTC) if now is None else now
    for _, crl in crls:
        if crl.issuer != cert.issuer:
            continue
        if crl.next_update_utc is not None and crl.next_update_utc < now:
            return "BadCertificateRevocationUnknown"
        if crl.get_revoked_certificate_by_serial_number(cert.serial_number) is not None:
            return "BadCertificateRevoked"
    return None


async def trust_validator(folder, on_refused=None, crl=None, *, peer: str = "client"):
    """asyncua's certificate validator for the controller: a client's certificate must be valid now,
    name the client's application URI, allow the client's key and extended key usages, and be in
    the trust folder or issued by a certificate in it (``TRUSTED_VALIDATION``); anything else ends
    the session request with BadCertificateUntrusted (or the check it failed), and
    ``on_refused(certificate, status)`` is told (the certificate as :func:`describe_certificate`
    gives it, the status code's name). With ``crl`` (:func:`revocation_lists`, read and checked
    here) a certificate revoked by its issuer's list is refused with BadCertificateRevoked.
    ``peer``: "client" (the controller checks its clients) or "server" (the client checks the
    controller: server key usage)."""
    from pathlib import Path

    from asyncua import ua
    from asyncua.common.utils import ServiceError
    from asyncua.crypto.truststore import TrustStore
    from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions

    trusted_certificates(folder)
    crls = [] if crl is None else revocation_lists(crl, folder)
    store = TrustStore([Path(folder)], [])  # revocation is checked below, by issuer
    await store.load()
    role = CertificateValidatorOptions.PEER_CLIENT if peer == "client" else CertificateValidatorOptions.PEER_SERVER
    validator = CertificateValidator(CertificateValidatorOptions.TRUSTED_VALIDATION | role, store)

    async def validate(cert, description):
        try:
            await validator(cert, description)
            why = revoked(cert, crls)
            if why is not None:
                raise ServiceError(getattr(ua.StatusCodes, why))
        except ServiceError as e:
            if on_refused is not None:
                on_refused(describe_certificate(cert), ua.StatusCode(e.code).name)
            raise

    return validate


def describe_certificate(cert) -> str:
    """A certificate as people compare them: its common name and SHA-256 fingerprint."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes

    names = cert.subject.get_attributes_for_oid(x509.NameOID.COMMON_NAME)
    name = str(names[0].value) if names else "no common name"
    return f"{name!r}, SHA-256 {cert.fingerprint(hashes.SHA256()).hex(':')[:23]}…"


def ua_error():
    from asyncua import ua

    return ua.UaError


def _user_manager(security: Security):
    from asyncua.crypto.permission_rules import User, UserRole
    from asyncua.server.user_managers import UserManager

    class _Users(UserManager):
        def get_user(self, iserver, username=None, password=None, certificate=None):  # noqa: ARG002
            if username == security.user and password == security.password:
                return User(role=UserRole.User)
            return None

    return _Users()


def run(source, sink, compensator, target_thickness: float, *, guard=None, on_step=None) -> int:
    """Read until the source is exhausted; return the number of compensator steps.

    ``guard`` (:class:`ncadapt.processes.skin.Interlocks`) decides which readings reach the
    compensator and bounds the commands it gives: a rejected reading holds the command in force
    (``sink.skip()``), too many in a row raise :class:`ncadapt.processes.skin.LoopStopped` with W1
    held. Without a guard only missing and non-finite readings are skipped (for tests of the
    compensators alone)."""
    n = 0
    for i, t in enumerate(source):
        if guard is not None:
            reason = guard.check(t)
            if reason is not None or compensator is None:
                sink.skip()
                if reason is not None:
                    guard.reject(reason, i)
                continue
        elif t is None or compensator is None or not math.isfinite(t):
            sink.skip()
            continue
        compensator.step(t - target_thickness)
        w1 = guard.bound(compensator) if guard is not None else compensator.w1_offset
        sink.write(w1)
        n += 1
        if on_step:
            on_step(n, t, w1)
    return n


class MachineLink:
    """Source and sink on an in-process virtual machine."""

    def __init__(self, machine, target_depth: float):
        self.machine, self.target_depth = machine, target_depth

    def __iter__(self):
        while not self.machine.done:
            t = self.machine.advance()
            if t is None and self.machine.done:
                return  # the path ended before the next reading
            yield t

    def write(self, offset: float) -> None:
        self.machine.command(self.target_depth + offset)

    def skip(self) -> None:
        pass


def run_in_process(machine, compensator, target_thickness: float, target_depth: float, *, guard=None) -> int:
    """Run a compensator on an in-process machine (a source of readings with ``done``,
    ``advance()`` and ``command(depth)``)."""
    link = MachineLink(machine, target_depth)
    return run(link, link, compensator, target_thickness, guard=guard)


class CsvSource:
    """Thickness readings from a CSV column ``thickness`` (empty or NaN: a rejected reading).
    ``header`` and ``row`` are the header and the current row as written, for :class:`CsvSink`."""

    def __init__(self, path):
        self.path = str(path)
        self.header: list[str] = []
        self.row: list[str] = []
        self.line = 1  # the line of the current row (1: the header)

    def __iter__(self):
        from ._io import csv_column, csv_reader
        from .errors import InputError

        r = csv_reader(self.path)
        self.header = next(r, [])
        head = [h.strip().lower() for h in self.header]
        if "thickness" not in head:
            raise InputError("missing column 'thickness'", self.path, 1)
        k = head.index("thickness")
        for row in r:
            self.row = row
            self.line = r.line_num
            v = row[k].strip() if k < len(row) else ""
            if not v:
                yield None
                continue
            try:
                yield float(v)
            except ValueError:
                raise InputError(
                    f"column thickness: expected a number, found {v!r}", self.path, r.line_num, csv_column(row, k)
                ) from None


class CsvSink:
    """W1 offsets, one row per reading (empty when the compensator did not step), written
    atomically by :meth:`close`. With ``source`` (a :class:`CsvSource`), each row is the reading's
    row as read with the offset in a column ``w1_offset`` (appended, or replaced if it has one)."""

    def __init__(self, path, source: CsvSource | None = None):
        self.path, self.source = path, source
        self._rows: list[tuple[list[str], str]] = []

    def _add(self, value: str) -> None:
        self._rows.append((list(self.source.row) if self.source else [], value))

    def write(self, offset: float) -> None:
        self._add(f"{offset:.6f}")

    def skip(self) -> None:
        self._add("")

    def close(self) -> None:
        import csv
        import io

        from ._io import atomic_write

        header = list(self.source.header) if self.source else []
        names = [h.strip().lower() for h in header]
        k = names.index("w1_offset") if "w1_offset" in names else len(header)
        header[k : k + 1] = ["w1_offset"]
        out = io.StringIO()
        w = csv.writer(out, lineterminator="\n")
        w.writerow(header)
        for row, value in self._rows:
            row = row + [""] * (len(header) - len(row))  # a short row is padded
            row[k : k + 1] = [value]
            w.writerow(row)
        atomic_write(self.path, out.getvalue().encode())


# ------------------------------------------------------------------------------------ OPC UA
async def serve_machine(
    machines,
    target_depth: float,
    *,
    endpoint: str = "opc.tcp://127.0.0.1:48400/ncadapt/",
    ready=None,
    poll: float = 0.0005,
    status: dict | None = None,
    ack_timeout: float = 5.0,
    security: Security | None = None,
    on_refused=None,
):
    """An OPC UA server playing the controller: runs each virtual machine in turn, publishing
    its readings and applying the client's W1 offsets. Publishes Sequence = −1 when all are done.
    ``Pockets`` tells the client how many pockets there are; a client that sets ``Fault`` stops
    the run with W1 held (``status["fault"]`` becomes True). A client that does not acknowledge a
    reading within ``ack_timeout`` seconds is taken as lost: W1 held, the run stopped
    (``status["lost"]`` becomes True) — the controller's watchdog. With ``security.trust`` a
    client certificate outside the trust folder is refused (:func:`trust_validator`;
    ``on_refused`` is told)."""
    from asyncua import Server, ua

    server = Server(user_manager=_user_manager(security)) if security is not None else Server()
    await server.init()
    server.set_endpoint(endpoint)
    if security is None:
        server.set_security_policy([ua.SecurityPolicyType.NoSecurity])
    else:
        await server.set_application_uri(SERVER_URI)
        server.set_security_policy([ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt])
        server.set_security_IDs(["Username"])
        await server.load_certificate(security.cert)
        await server.load_private_key(security.key)
        if security.trust is not None:
            server.set_certificate_validator(await trust_validator(security.trust, on_refused, security.crl))
    idx = await server.register_namespace(NAMESPACE)
    obj = await server.nodes.objects.add_object(idx, "Controller")
    thick = await obj.add_variable(idx, "Thickness", math.nan)
    seq = await obj.add_variable(idx, "Sequence", 0, varianttype=ua.VariantType.Int64)
    w1 = await obj.add_variable(idx, "W1Offset", 0.0)
    ack = await obj.add_variable(idx, "Ack", 0, varianttype=ua.VariantType.Int64)
    fault = await obj.add_variable(idx, "Fault", False, varianttype=ua.VariantType.Boolean)
    await obj.add_variable(idx, "Pockets", len(machines), varianttype=ua.VariantType.Int64)
    for v in (w1, ack, fault):
        await v.set_writable()
    async with server:
        if ready is not None:
            ready.set()
        n = 0
        for m in machines:
            while not m.done:
                t = m.advance()
                n += 1
                await thick.write_value(math.nan if t is None else float(t))
                await seq.write_value(n, ua.VariantType.Int64)
                deadline = time.monotonic() + ack_timeout
                while await ack.read_value() != n:
                    if time.monotonic() > deadline:
                        if status is not None:
                            status["lost"] = True
                        await seq.write_value(0, ua.VariantType.Int64)
                        return
                    await asyncio.sleep(poll)
                if await fault.read_value():
                    # the client stopped the loop: hold W1 (no new command) and stop feeding
                    if status is not None:
                        status["fault"] = True
                    await seq.write_value(0, ua.VariantType.Int64)
                    await asyncio.sleep(0.05)
                    return
                if t is not None:
                    m.command(target_depth + float(await w1.read_value()))
            # a new pocket: the client starts its compensator afresh
            n += 1
            await thick.write_value(math.nan)
            await seq.write_value(-n, ua.VariantType.Int64)
            deadline = time.monotonic() + ack_timeout
            while await ack.read_value() != -n:
                if time.monotonic() > deadline:
                    if status is not None:
                        status["lost"] = True
                    await seq.write_value(0, ua.VariantType.Int64)
                    return
                await asyncio.sleep(poll)
        await seq.write_value(0, ua.VariantType.Int64)
        await asyncio.sleep(0.05)


class ControllerLost(Exception):
    """The OPC UA controller stopped publishing readings, or the connection broke."""


class ServerUntrusted(Exception):
    """The controller presents another certificate than the one the client was given: the client
    refuses it (it could be another machine, or a man in the middle)."""


class ServerRefused(ServerUntrusted):
    """The controller's certificate is not trusted by the client's trust folder, or is revoked:
    the client refuses the session (``status``: the OPC UA status code's name)."""

    def __init__(self, message: str, status: str):
        super().__init__(message)
        self.status = status


class ConnectionRefused(Exception):
    """The controller refused the session: no endpoint with the client's security, or the user
    name, password or certificate rejected."""


async def connect(url: str, timeout: float = 30.0, *, request_timeout: float = 4.0, security: Security | None = None):
    """An asyncua client connected to ``url``, retrying (0.1 s, doubling to 1 s) for up to
    ``timeout`` seconds while the server is still starting (refused or timed-out connections);
    the last error once the time is up."""
    from asyncua import Client

    deadline = time.monotonic() + max(0.0, float(timeout))
    delay = 0.1
    refusal: list = []
    validator = None
    if security is not None and security.trust is not None:
        validator = await trust_validator(
            security.trust, lambda cert, status: refusal.append((cert, status)), security.crl, peer="server"
        )
    while True:
        client = Client(url=url, timeout=request_timeout)
        client.certificate_validator = validator
        if security is not None:
            from asyncua import ua
            from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

            client.application_uri = CLIENT_URI
            await client.set_security(
                SecurityPolicyBasic256Sha256,
                security.cert,
                security.key,
                server_certificate=security.peer_cert,
                mode=ua.MessageSecurityMode.SignAndEncrypt,
            )
            client.set_user(security.user)
            client.set_password(security.password)
        try:
            if security is not None and security.peer_cert is not None:
                await check_server_certificate(url, security.peer_cert, request_timeout)
            await client.connect()
            return client
        except ServerUntrusted:
            raise
        except ua_error() as e:
            with contextlib.suppress(Exception):
                await client.disconnect()
            if refusal:
                cert, status = refusal[-1]
                raise ServerRefused(
                    f"the controller presents the certificate {cert}, refused by the trust folder "
                    f"{security.trust}"
                    + (f" and the revocation lists {security.crl}" if security.crl else "")  # type: ignore[union-attr]
                    + f": {status}",
                    status,
                ) from None
            raise ConnectionRefused(str(e).strip() or type(e).__name__) from None
        except (TimeoutError, OSError):
            with contextlib.suppress(Exception):
                await client.disconnect()
            if time.monotonic() + delay > deadline:
                raise
            await asyncio.sleep(delay)
            delay = min(2 * delay, 1.0)


async def check_server_certificate(url: str, expected: str, request_timeout: float = 4.0) -> None:
    """Refuse a controller whose endpoint for Basic256Sha256 SignAndEncrypt presents another
    certificate than ``expected`` (a DER or PEM file): :class:`ServerUntrusted` naming both. The
    endpoints are read over the discovery channel every OPC UA server offers without security;
    asyncua's own check comes only after the secure channel, which a controller with another key
    cannot open (the client would only see a timeout)."""
    from asyncua import Client, ua
    from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
    from asyncua.crypto.uacrypto import load_certificate
    from cryptography import x509
    from cryptography.hazmat.primitives.serialization import Encoding

    want = await load_certificate(expected)
    endpoints = await Client(url=url, timeout=request_timeout).connect_and_get_server_endpoints()
    secured = [
        e
        for e in endpoints
        if e.SecurityPolicyUri == SecurityPolicyBasic256Sha256.URI
        and e.SecurityMode == ua.MessageSecurityMode.SignAndEncrypt
    ]
    if not secured:
        return  # no such endpoint: the session is refused as such (ConnectionRefused)
    der = secured[0].ServerCertificate or b""
    der = der[: int.from_bytes(der[2:4], "big") + 4]  # the first certificate of a chain
    if der == want.public_bytes(Encoding.DER):
        return
    try:
        got = describe_certificate(x509.load_der_x509_certificate(der))
    except ValueError:
        got = "no readable certificate"
    raise ServerUntrusted(
        f"the controller presents the certificate {got}, not the one given ({expected}: "
        f"{describe_certificate(want)}); refused"
    )


async def run_opcua(
    url: str,
    make_compensator,
    target_thickness: float,
    *,
    pockets: int | None = None,
    poll: float = 0.0005,
    latencies: list | None = None,
    make_guard=None,
    connect_timeout: float = 30.0,
    info: dict | None = None,
    stale_timeout: float = 5.0,
    security: Security | None = None,
) -> int:
    """The compensator as an OPC UA client. ``make_compensator()`` gives a fresh compensator for
    each pocket (a negative Sequence announces the next one), ``make_guard()`` its interlocks
    (:class:`ncadapt.processes.skin.Interlocks`, the same as in a replay). ``pockets``: how many to
    finish; None reads the controller's ``Pockets``. Returns the number of steps; ``latencies``
    collects, per reading, the seconds from seeing the new Sequence to writing Ack; ``info`` gets
    ``pockets``, ``rejected`` and ``max_abs_w1``.

    When the interlocks stop the loop (persistent gauge faults) the client writes ``Fault`` = true
    on the controller — its signal to hold W1 and stop feeding — acknowledges the reading, and
    raises :class:`ncadapt.processes.skin.LoopStopped`. When the controller publishes no new
    reading for ``stale_timeout`` seconds, or the connection breaks, :class:`ControllerLost` is
    raised (the client's watchdog; the controller's own holds W1 when the Acks stop)."""
    from asyncua import ua

    info = {} if info is None else info
    client = await connect(url, connect_timeout, security=security)
    try:
        idx = await client.get_namespace_index(NAMESPACE)
        obj = await client.nodes.objects.get_child(f"{idx}:Controller")
        nodes = {
            name: await obj.get_child(f"{idx}:{name}") for name in ("Thickness", "Sequence", "W1Offset", "Ack", "Fault")
        }
        if pockets is None:
            pockets = int(await (await obj.get_child(f"{idx}:Pockets")).read_value())
            if pockets < 1:
                raise ValueError(f"the controller announces {pockets} pockets")
        info["pockets"] = pockets
        try:
            await _exchange(
                nodes, make_compensator, make_guard, target_thickness, pockets, poll, latencies, stale_timeout, info
            )
        except (TimeoutError, OSError, ua.UaError) as e:
            raise ControllerLost(f"the connection to the controller broke: {e or type(e).__name__}") from None
    finally:
        with contextlib.suppress(Exception):
            await client.disconnect()
    return info["steps"]


async def _exchange(
    nodes, make_compensator, make_guard, target_thickness, pockets, poll, latencies, stale_timeout, info
) -> None:
    """The client's side of the exchange (see :func:`run_opcua`); the totals go to ``info``."""
    from asyncua import ua

    thick, seq, w1, ack, fault = (nodes[k] for k in ("Thickness", "Sequence", "W1Offset", "Ack", "Fault"))
    totals = {"steps": 0, "rejected": 0, "max_abs_w1": 0.0}

    def add(comp, guard) -> None:
        if comp is not None:
            totals["steps"] += comp.steps
        if guard is not None:
            totals["rejected"] += guard.rejected
            totals["max_abs_w1"] = max(totals["max_abs_w1"], guard.max_abs_w1)

    comp = make_compensator()
    guard = make_guard() if make_guard is not None else None
    last, done, i = 0, 0, 0
    seen = time.monotonic()
    while done < pockets:
        s = await seq.read_value()
        if s == last or s == 0:
            if time.monotonic() - seen > stale_timeout:
                raise ControllerLost(f"the controller published no new reading for {stale_timeout:g} s")
            await asyncio.sleep(poll)
            continue
        seen = time.monotonic()
        t0 = time.perf_counter()
        last = s
        if s < 0:
            done += 1
            add(comp, guard)
            comp = make_compensator()
            guard = make_guard() if make_guard is not None else None
        else:
            t = await thick.read_value()
            value = None
            try:
                if guard is not None:
                    reason = guard.check(None if t is None or not math.isfinite(t) else t)
                    if reason is not None:
                        guard.reject(reason, i)
                    elif comp is not None:
                        comp.step(t - target_thickness)
                        value = guard.bound(comp)
                elif comp is not None and math.isfinite(t):
                    comp.step(t - target_thickness)
                    value = comp.w1_offset
            except Exception:
                # the interlocks stopped the loop: tell the controller, acknowledge, report
                await fault.write_value(ua.DataValue(ua.Variant(True, ua.VariantType.Boolean)))
                await ack.write_value(ua.DataValue(ua.Variant(int(s), ua.VariantType.Int64)))
                add(comp, guard)
                info.update(totals)
                raise
            i += 1
            if value is not None:
                await w1.write_value(ua.DataValue(ua.Variant(float(value), ua.VariantType.Double)))
        await ack.write_value(ua.DataValue(ua.Variant(int(s), ua.VariantType.Int64)))
        if latencies is not None:
            latencies.append(time.perf_counter() - t0)
    info.update(totals)
