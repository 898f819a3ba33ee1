"""``ncadapt skin simulate``: mirror milling of thin skins on the virtual testbed
(see :mod:`ncadapt.processes.skin` and :mod:`ncadapt.sim.skin`)."""

from __future__ import annotations

from pathlib import Path

import click

from .. import constants
from ..errors import InputError
from ..processes.skin import GAUGE_LIMIT as ps_limit
from ..processes.skin import GAUGES, MAX_FAULTS, STUCK, W1_STEP_MAX
from ._common import FiniteRange, check_outputs, handle_errors, json_option, seed_option, summary, write_json

#: the testbed's conditions (ncadapt.sim.skin.VARIANTS, named here so the CLI loads without the testbed)
VARIANT_NAMES = ("paper", "fixed-rate", "spiral", "fast", "servo")


@click.group()
def skin() -> None:
    """Mirror milling of thin skins: real-time wall-thickness compensation."""


@skin.command("simulate")
@click.option(
    "--method",
    type=click.Choice(["none", "mirror", "secant", "kalman"]),
    default=None,
    help="Compensator (kalman: ours); default kalman, the mirror on the fixed-rate gauge variant.",
)
@click.option(
    "--variant",
    type=click.Choice(list(VARIANT_NAMES)),
    default="paper",
    show_default=True,
    help="Testbed condition: the paper's; a fixed-rate gauge (20–25 Hz); a spiral-out path; "
    "6000 mm/min with 60 ms; W1 as a 30 ms first-order servo.",
)
@click.option(
    "--noise",
    type=FiniteRange(min=0, max=0.1),
    default=0.005,
    show_default=True,
    help="Gauge noise σ, mm (0 to 0.1: a third of the gauge's 0.3 mm tolerance).",
)
@click.option(
    "--latency-ms",
    type=FiniteRange(min=0, max=1000),
    default=45.0,
    show_default=True,
    help="Dead time from reading to axis motion, ms (0 to 1000: 25 mm of path at the testbed's feed).",
)
@seed_option
@click.option("--protocol", is_flag=True, help="The paper's noise-free protocol at the checkpoints instead.")
@json_option
@click.option(
    "--report",
    "report_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="HTML report with the error along the toolpath.",
)
@handle_errors
def simulate(method, variant, noise, latency_ms, seed, protocol, json_path, report_path):
    """Finish the testbed's two pockets with a compensator; errors at the 13 checkpoints of each."""
    from ..processes import skin as ps
    from ..sim import skin as sk

    if method is None:
        method = ps.default_method("fixed-rate" if variant == "fixed-rate" else "fresh")
    if (report_path or protocol) and variant != "paper":
        raise click.UsageError("--report and --protocol are the paper's condition; leave out --variant")
    check_outputs({}, {"--json": json_path, "--report": report_path})
    if protocol:
        if method in ("none",):
            raise click.UsageError("the protocol compares compensators; choose one")
        r = sk.protocol(method)
        summary(f"{method}: max |error| after {r['compensations']} compensations {r['max_abs_error'] * 1000:.4g} µm")
        if json_path:
            write_json(json_path, r)
        return
    from ._common import progress_bar

    runs = 1 + (3 if report_path else 0)
    with progress_bar(f"skin {method}", runs) as advance:
        run = sk.run(
            method,
            noise=noise,
            latency_ms=latency_ms,
            seed=seed,
            variant=variant,
            on_progress=lambda done, total: advance(done / total),
        )
        others = {}
        if report_path:
            for k, m in enumerate(x for x in ("none", "mirror", "secant", "kalman") if x != method):
                others[m] = sk.run(
                    m,
                    noise=noise,
                    latency_ms=latency_ms,
                    seed=seed,
                    on_progress=lambda done, total, _k=k: advance(1 + _k + done / total),
                )
    d = run.as_dict()
    d["variant"] = variant
    summary(
        f"{method}{'' if variant == 'paper' else ' (' + variant + ')'}: |error| at 2 × 13 checkpoints max {d['max_abs_error'] * 1000:.1f} µm, "
        f"min {d['min_abs_error'] * 1000:.1f} µm, mean {d['mean_abs_error'] * 1000:.1f} µm; "
        f"{d['compensator_steps']} steps, {d['fallbacks']} fallbacks, {d['rejected_readings']} readings rejected"
    )
    if json_path:
        write_json(json_path, d)
    if report_path:
        _report(report_path, run, others)


def _report(path, run, others=None) -> None:
    import numpy as np

    from ..report import figure_png, page, pyplot, table, write
    from ..sim import skin as sk

    plt = pyplot()

    fig, axes = plt.subplots(1, len(run.path_errors), figsize=(11, 3.8), squeeze=False)
    for k, (ax, err) in enumerate(zip(axes[0], run.path_errors)):
        p = sk.toolpath(k)
        sc = ax.scatter(p[:, 0], p[:, 1], c=np.asarray(err) * 1000, s=1, cmap="RdBu_r", vmin=-50, vmax=50)
        cps = [c for c in run.checkpoints if c["pocket"] == k + 1]
        ax.plot([c["x"] - sk.POCKETS[k][0] for c in cps], [c["y"] - sk.POCKETS[k][1] for c in cps], "k+", ms=10)
        ax.set_title(f"pocket {k + 1}", fontsize=10)
        ax.set_aspect("equal")
        ax.set_xlabel("x, mm")
    fig.colorbar(sc, ax=axes[0].tolist(), label="thickness error, µm")
    d = run.as_dict()
    # every method on the same seed, noise and dead time, and the paper's noise-free protocol
    methods = ("none", "mirror", "secant", "kalman")
    others = others or {}
    runs = {
        m: (
            run
            if m == run.method
            else others.get(m) or sk.run(m, noise=run.noise, latency_ms=run.latency_ms, seed=run.seed)
        ).as_dict()
        for m in methods
    }
    rows = [
        (
            c["pocket"],
            f"{c['x']:.0f}",
            f"{c['y']:.0f}",
            *(f"{runs[m]['checkpoints'][i]['error'] * 1000:+.1f}" for m in methods),
        )
        for i, c in enumerate(run.checkpoints)
    ]
    for key in ("max_abs_error", "min_abs_error", "mean_abs_error"):
        rows.append((key.split("_")[0] + " |error|", "", "", *(f"{runs[m][key] * 1000:.1f}" for m in methods)))
    rows.append(("fallbacks", "", "", *(str(runs[m]["fallbacks"]) for m in methods)))
    proto = [(m, f"{sk.protocol(m)['max_abs_error'] * 1000:.4g}") for m in ("mirror", "secant", "kalman")]
    sections = [
        (
            "Result",
            table(
                [
                    ("method", run.method),
                    ("gauge noise σ, mm", run.noise),
                    ("dead time, ms", run.latency_ms),
                    ("max |error|, µm", f"{d['max_abs_error'] * 1000:.1f}"),
                    ("mean |error|, µm", f"{d['mean_abs_error'] * 1000:.1f}"),
                    ("fallbacks", d["fallbacks"]),
                ],
                ["", "value"],
            ),
        ),
        ("Error along the toolpath", figure_png(fig)),
        ("Checkpoints: every method on the same seed (error, µm)", table(rows, ["pocket", "x, mm", "y, mm", *methods])),
        (
            "The paper's noise-free protocol: max |error| after the second compensation, µm",
            table(proto, ["method", "max |error|, µm"]),
        ),
    ]
    write(path, page(f"Skin mirror milling: {run.method}", "ncadapt skin testbed", sections))


@skin.command("correct")
@click.argument("program", type=click.Path(exists=True, dir_okay=False, path_type=Path))
@click.option(
    "--thickness",
    "map_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    required=True,
    help="Thickness map: CSV with columns x,y,thickness (mm), on a grid or scattered.",
)
@click.option(
    "--target",
    type=FiniteRange(min=0, min_open=True, max=ps_limit),
    required=True,
    help=f"Target wall thickness T, mm (> 0, at most {ps_limit:g}: the gauge's limit).",
)
@click.option(
    "--allowance",
    type=FiniteRange(min=0, max=ps_limit),
    default=0.0,
    show_default=True,
    help=f"Material the finishing pass was planned to remove (0: the map is after finishing; a second "
    f"round), mm (0 to {ps_limit:g}).",
)
@click.option(
    "--into",
    type=click.Choice(["-z", "+z"]),
    default="-z",
    show_default=True,
    help="Direction in which the tool cuts deeper.",
)
@click.option(
    "-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True, help="Corrected program to write."
)
@click.option(
    "--limit",
    type=FiniteRange(min=0, min_open=True),
    default=constants.LIMIT,
    show_default=True,
    help="Refuse if any correction exceeds this, mm.",
)
@click.option(
    "--outside",
    type=click.Choice(["error", "clamp", "extrapolate"]),
    default="error",
    show_default=True,
    help="Program points outside the map.",
)
@json_option
@handle_errors
def correct(program, map_path, target, allowance, into, output, limit, outside, json_path):
    """Correct a finishing PROGRAM from a thickness MAP measured after the previous pass: the
    tool goes deeper by the excess thickness − target − allowance (offline mode)."""
    import numpy as np

    from .. import nc
    from ..processes import skin as ps
    from ._common import echo_err, progress

    check_outputs({"input program": program, "thickness map": map_path}, {"-o": output, "--json": json_path})
    with progress() as say:
        say(f"reading {map_path}")
        field, excess = ps.thickness_field(map_path, target, allowance=allowance, into=into, outside=outside)
        say(f"reading {program}")
        prog = nc.read(program)
        c = prog.correct_to(output, field, limit=limit, progress=say)
    summary(f"{program} -> {output}")
    summary(
        f"  map: {len(excess)} points, excess thickness min {excess.min():+.4f} max {excess.max():+.4f} "
        f"mean {excess.mean():+.4f} mm"
    )
    summary(
        f"  blocks changed {c.blocks_changed:,}, lines added {c.lines_added:,}; displacement max "
        f"{c.max_displacement:.4f} mm, mean {c.mean_displacement:.4f} mm"
    )
    if allowance > 0:
        summary(
            f"  not corrected: the finishing pass's own deflection under the {allowance:g} mm it removes "
            "(largest mid-pocket); measure the finished wall before a second round (`skin correct` on "
            "the corrected program with that map and --allowance 0): a light re-cut can over-cut a wall "
            "on constant-force supports"
        )
    else:
        summary(
            "  the re-cut engages the residual plus the deflection the previous pass had; a light re-cut "
            "cuts with almost no force while constant-force supports still push the wall onto the "
            "cutter, so it can over-cut: measure again after it"
        )
    for w in c.warnings:
        echo_err(f"  warning: {w}")
    if json_path:
        d = {
            "input": str(program),
            "output": str(output),
            "thickness": str(map_path),
            "target": target,
            "allowance": allowance,
            "into": into,
            "map_points": int(len(excess)),
            "excess_min": float(np.min(excess)),
            "excess_max": float(np.max(excess)),
            "excess_mean": float(np.mean(excess)),
        }
        d.update(c.as_dict())
        write_json(json_path, d)


_ENDPOINT = "opc.tcp://127.0.0.1:48400/ncadapt/"
#: where the OPC UA password is read from (never a command-line argument: it would show in ps)
PASSWORD_ENV = "NCADAPT_OPCUA_PASSWORD"

_FILE = click.Path(exists=True, dir_okay=False, path_type=Path)


def _security(insecure, cert, key, user, peer_cert=None, *, client: bool, trust=None, crl=None):
    """The exchange's security from the options: Basic256Sha256 SignAndEncrypt with certificates
    and a user, or NoSecurity with --insecure (exactly one). The trust folder and the revocation
    lists are read and checked here (exit 2 before anything is served or connected)."""
    from .. import loop as lp

    given = [
        n
        for n, v in (("--cert", cert), ("--key", key), ("--user", user), ("--trust", trust), ("--crl", crl))
        + ((("--server-cert", peer_cert),) if client else ())
        if v is not None
    ]
    if insecure:
        if given:
            raise click.UsageError(
                f"--insecure and {', '.join(given)} exclude each other (NoSecurity has no certificates)"
            )
        return None
    if crl is not None and trust is None:
        raise click.UsageError(
            "--crl needs --trust: the folder holding the certificate of each list's issuer (its signature is checked)"
        )
    needed = ["--cert", "--key", "--user"]
    if client and peer_cert is None and trust is None:
        needed.append("--server-cert (or --trust)")
    missing = [n for n in needed if n not in given]
    if missing:
        raise click.UsageError(
            f"the exchange is secured (Basic256Sha256, SignAndEncrypt): give {', '.join(missing)} "
            f"(`ncadapt skin certs DIR` makes certificates) and the password in {PASSWORD_ENV}, "
            "or --insecure for NoSecurity"
        )
    import os

    password = os.environ.get(PASSWORD_ENV)
    if not password:
        raise click.UsageError(f"the password for --user {user!r} goes in the environment variable {PASSWORD_ENV}")
    if trust is not None:
        lp.trusted_certificates(trust)
        if crl is not None:
            lp.revocation_lists(crl, trust)
    return lp.Security(
        str(cert),
        str(key),
        user,
        password,
        str(peer_cert) if peer_cert else None,
        str(trust) if trust is not None else None,
        str(crl) if crl is not None else None,
    )


def _security_options(client: bool):
    def deco(f):
        opts = [
            click.option(
                "--insecure", is_flag=True, help="No OPC UA security (NoSecurity): only on a closed machine network."
            ),
            click.option("--cert", type=_FILE, help="This side's application certificate (DER) for Basic256Sha256."),
            click.option("--key", type=_FILE, help="Its private key (PEM)."),
            click.option("--user", help=f"User name of the session (password in {PASSWORD_ENV})."),
        ]
        if client:
            opts += [
                click.option(
                    "--server-cert",
                    "peer_cert",
                    type=_FILE,
                    help="The controller's certificate (DER): a controller presenting another one is refused.",
                ),
                click.option(
                    "--trust",
                    type=click.Path(exists=True, file_okay=False, path_type=Path),
                    help="Folder of certificates (DER or PEM): the controller's certificate must be in it or issued "
                    "by one in it (with or instead of --server-cert).",
                ),
            ]
        else:
            opts.append(
                click.option(
                    "--trust",
                    type=click.Path(exists=True, file_okay=False, path_type=Path),
                    help="Folder of the client certificates (DER or PEM) the controller accepts; a client whose "
                    "certificate is not in it (nor issued by one in it) is refused. Without it, any client "
                    "certificate with the right user and password is accepted.",
                )
            )
        opts.append(
            click.option(
                "--crl",
                type=click.Path(exists=True, path_type=Path),
                help="Certificate revocation lists (a file, or a folder of *.crl, *.pem, *.der; PEM or DER), with "
                "--trust: a peer certificate its issuer revoked is refused. Each list must be signed by a "
                "certificate of --trust and not expired (else exit 2 at start).",
            )
        )
        for o in reversed(opts):
            f = o(f)
        return f

    return deco


def _quiet_asyncua() -> None:
    """Silence asyncua's own log: its notes on the missing security policy (documented in
    docs/skin.md instead) and the tracebacks of failures the commands report themselves."""
    import logging

    for name in ("asyncua", "asyncuagds"):  # asyncuagds: its trust store's notes
        logging.getLogger(name).setLevel(logging.CRITICAL)


@skin.command("loop")
@click.option(
    "--method",
    type=click.Choice(["mirror", "secant", "kalman"]),
    default=None,
    help="Compensator (kalman: ours); default kalman with a fresh gauge, the mirror with a fixed-rate one.",
)
@click.option(
    "--gauge",
    type=click.Choice(list(GAUGES)),
    default="fresh",
    show_default=True,
    help="fresh: each reading reflects the latest W1 command (the paper's controller); fixed-rate: "
    "readings at a fixed rate, most cut before the latest command landed.",
)
@click.option(
    "--target",
    type=FiniteRange(min=0.01, max=ps_limit),
    required=True,
    help=f"Target wall thickness T_g, mm (0.01 to {ps_limit:g}, the gauge's limit).",
)
@click.option(
    "--depth",
    type=FiniteRange(min=0.001, max=ps_limit),
    required=True,
    help=f"Target depth a_g = T_s − T_g of the finishing pass, mm (0.001 to {ps_limit:g}).",
)
@click.option(
    "--noise",
    type=FiniteRange(min=1e-6, max=0.3),
    default=0.005,
    show_default=True,
    help="The gauge's noise σ, mm (kalman and secant; 1e-6 to 0.3, the gauge's tolerance).",
)
@click.option(
    "--w1-max",
    type=FiniteRange(min=0, min_open=True),
    default=None,
    help="Bound of the W1 command |W1|, mm; below --target (a W1 of T_g would cut through the wall). "
    "Default min(2 × --depth, --target / 2).",
)
@click.option(
    "--w1-step-max",
    type=FiniteRange(min=0, min_open=True, max=ps_limit),
    default=W1_STEP_MAX,
    show_default=True,
    help="Bound of the change of W1 per reading, mm.",
)
@click.option(
    "--max-faults",
    type=click.IntRange(min=1, max=10**6),
    default=MAX_FAULTS,
    show_default=True,
    help="Rejected readings in a row (NaN, ≤ 0, above 10 mm, more than 0.3 mm from --target, "
    "--stuck identical in a row) that stop the loop with W1 held (exit 1).",
)
@click.option(
    "--stuck",
    type=click.IntRange(min=2, max=10**6),
    default=STUCK,
    show_default=True,
    help="Identical readings in a row that make a stuck gauge (the N-th and later are rejected).",
)
@click.option(
    "--replay",
    "replay_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="Recorded gauge readings: CSV with a column thickness (empty or NaN: rejected).",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    help="With --replay: the readings' rows with the W1 offset commanded after each in a column "
    "w1_offset (empty where the command in force was held).",
)
@click.option(
    "--opcua",
    "url",
    metavar="URL",
    help="The controller's OPC UA server (namespace urn:ncadapt:skin, object Controller).",
)
@click.option(
    "--pockets",
    type=click.IntRange(min=1),
    default=None,
    help="With --opcua: pockets to finish before stopping (default: the controller's Pockets).",
)
@click.option(
    "--connect-timeout",
    type=FiniteRange(min=0, max=3600),
    default=30.0,
    show_default=True,
    help="With --opcua: seconds to keep retrying while the server is still starting (0: one try).",
)
@click.option(
    "--stale-timeout",
    type=FiniteRange(min=0.1, max=3600),
    default=5.0,
    show_default=True,
    help="With --opcua: seconds without a new reading after which the controller is taken as lost (exit 1).",
)
@_security_options(client=True)
@json_option
@handle_errors
def loop_cmd(
    method,
    gauge,
    target,
    depth,
    noise,
    w1_max,
    w1_step_max,
    max_faults,
    stuck,
    replay_path,
    output,
    url,
    pockets,
    connect_timeout,
    stale_timeout,
    insecure,
    cert,
    key,
    user,
    peer_cert,
    trust,
    crl,
    json_path,
):
    """Run a compensator in the loop: gauge readings in, W1 offsets out — replayed from a CSV, or
    live as an OPC UA client of the controller. Both go through the same interlocks: the gauge
    filter, bounds on W1 and its step, and a stop on persistent faults."""
    import asyncio

    import numpy as np

    from .. import loop as lp
    from ..processes import skin as ps

    if (replay_path is None) == (url is None):
        raise click.UsageError("give exactly one of --replay FILE or --opcua URL")
    if method is None:
        method = ps.default_method(gauge)
    if (replay_path is None) != (output is None):
        raise click.UsageError("--replay and -o go together")
    if url is None and (pockets is not None or insecure or cert or key or user or peer_cert or trust or crl):
        raise click.UsageError(
            "--pockets, --insecure, --cert, --key, --user, --server-cert, --trust and --crl go with --opcua"
        )
    security = (
        _security(insecure, cert, key, user, peer_cert, client=True, trust=trust, crl=crl) if url is not None else None
    )
    if w1_max is not None and not w1_max < target:
        raise click.BadParameter(
            f"{w1_max:g} mm is not below --target {target:g} mm: a W1 of the target "
            "thickness would cut through the wall",
            param_hint="'--w1-max'",
        )
    check_outputs({"gauge readings": replay_path}, {"-o": output, "--json": json_path})
    comps, guards = [], []

    def fresh():
        comps.append(ps.make(method, depth, noise=noise, max_step=w1_step_max))
        return comps[-1]

    def guard():
        guards.append(
            ps.Interlocks(target, depth, w1_max=w1_max, w1_step_max=w1_step_max, max_faults=max_faults, stuck=stuck)
        )
        return guards[-1]

    d = {"method": method, "gauge": gauge, "target": target, "depth": depth, "noise": noise}
    stopped = None
    if replay_path is not None:
        source = lp.CsvSource(replay_path)
        sink = lp.CsvSink(output, source)
        offsets = []
        try:
            steps = lp.run(source, sink, fresh(), target, guard=guard(), on_step=lambda n, t, w: offsets.append(w))
        except ps.LoopStopped as e:
            stopped = e
            where = f"{replay_path}:{source.line}"
        else:
            sink.close()
        d.update(source=str(replay_path), output=str(output))
        if stopped is None:
            summary(f"{replay_path}: {steps} readings stepped -> {output}")
    else:
        from asyncua import ua

        _quiet_asyncua()
        lat: list = []
        info: dict = {}
        try:
            steps = asyncio.run(
                lp.run_opcua(
                    url,
                    fresh,
                    target,
                    pockets=pockets,
                    latencies=lat,
                    make_guard=guard,
                    connect_timeout=connect_timeout,
                    info=info,
                    stale_timeout=stale_timeout,
                    security=security,
                )
            )
        except ps.LoopStopped as e:
            stopped, where, steps = e, url, info.get("steps", 0)
        except lp.ServerRefused as e:
            raise InputError(f"{e} (--trust, --crl)", url) from None
        except lp.ServerUntrusted as e:
            raise InputError(f"{e} (--server-cert)", url) from None
        except lp.ConnectionRefused as e:
            if "BadCertificateRevoked" in str(e):
                raise InputError(
                    f"the controller refused the session: this client's certificate ({cert}) is revoked by its "
                    "issuer's revocation list (skin serve --crl)",
                    url,
                ) from None
            if "BadCertificateUntrusted" in str(e):
                raise InputError(
                    f"the controller refused the session: it does not trust this client's certificate "
                    f"({cert}): add the certificate to the controller's trust folder (skin serve --trust)",
                    url,
                ) from None
            raise InputError(
                f"the controller refused the session: {e}; check --cert, --key, --server-cert, --user "
                f"and {PASSWORD_ENV} (or --insecure on both sides)",
                url,
            ) from None
        except lp.ControllerLost as e:
            from ..errors import RefusedError

            raise RefusedError(f"{url}: {e}; the loop stopped (the controller's watchdog holds W1)") from None
        except (TimeoutError, OSError) as err:
            raise InputError(f"cannot reach the controller: {err or type(err).__name__}", url) from None
        except (ua.UaError, ValueError) as err:
            raise InputError(
                f"not an ncadapt skin controller (namespace {lp.NAMESPACE}, object Controller "
                f"with Thickness, Sequence, W1Offset, Ack, Fault, Pockets): {err}",
                url,
            ) from None
        offsets = []
        pockets = info.get("pockets", pockets)
        d.update(
            source=url,
            pockets=pockets,
            latency_median_ms=float(np.median(lat) * 1e3) if lat else None,
            latency_p99_ms=float(np.percentile(lat, 99) * 1e3) if lat else None,
        )
        if lat:
            summary(
                f"{url}: {len(lat)} readings, latency median {d['latency_median_ms']:.2f} ms, "
                f"p99 {d['latency_p99_ms']:.2f} ms"
            )
    if stopped is not None:
        from ..errors import RefusedError

        signal = "; Fault set on the controller" if url is not None else "; nothing written"
        raise RefusedError(
            f"{where}: {stopped}{signal}",
            [
                f"rejected readings: {sum(g.rejected for g in guards)}",
                *(f"{k}: {v}" for g in guards[-1:] for k, v in g.reasons.items()),
            ],
        )
    fallbacks = sum(c.fallbacks for c in comps)
    rejected = sum(g.rejected for g in guards)
    max_abs_w1 = max((g.max_abs_w1 for g in guards), default=0.0)
    clamped = sum(g.clamped for g in guards)
    d.update(
        steps=steps,
        fallbacks=fallbacks,
        rejected=rejected,
        max_abs_w1=max_abs_w1,
        clamped=clamped,
        w1_max=guards[0].w1_max if guards else w1_max,
        w1_step_max=w1_step_max,
        max_faults=max_faults,
        stuck=stuck,
    )
    if offsets:
        d.update(w1_offset_min=float(min(offsets)), w1_offset_max=float(max(offsets)))
    summary(
        f"{method}: {steps} steps, {fallbacks} fallbacks, {rejected} readings rejected, {clamped} commands "
        f"bounded; |W1| max {max_abs_w1:.4f} mm"
        + (f" (W1 offset {min(offsets):+.4f} .. {max(offsets):+.4f} mm)" if offsets else "")
    )
    if json_path:
        write_json(json_path, d)


@skin.command("serve")
@click.option("--endpoint", default=_ENDPOINT, show_default=True, help="Where the virtual controller listens.")
@click.option(
    "--noise",
    type=FiniteRange(min=0, max=0.1),
    default=0.005,
    show_default=True,
    help="Gauge noise σ, mm (0 to 0.1: a third of the gauge's 0.3 mm tolerance).",
)
@click.option(
    "--latency-ms",
    type=FiniteRange(min=0, max=1000),
    default=45.0,
    show_default=True,
    help="Dead time from reading to axis motion, ms (0 to 1000: 25 mm of path at the testbed's feed).",
)
@seed_option
@click.option(
    "--ack-timeout",
    type=FiniteRange(min=0.1, max=3600),
    default=5.0,
    show_default=True,
    help="Seconds to wait for the client's Ack before holding W1 and stopping (the watchdog).",
)
@_security_options(client=False)
@json_option
@handle_errors
def serve(endpoint, noise, latency_ms, seed, ack_timeout, insecure, cert, key, user, trust, crl, json_path):
    """Play the controller of the testbed on OPC UA: publish its gauge readings, apply the W1
    offsets a client writes (try `skin loop --opcua` against it before a real controller), and
    report the errors at the 13 checkpoints of each pocket when both pockets are finished."""
    import asyncio
    import threading

    from .. import loop as lp
    from ..sim import skin as sk

    security = _security(insecure, cert, key, user, client=False, trust=trust, crl=crl)
    check_outputs({}, {"--json": json_path})
    _quiet_asyncua()
    ms = sk.machines(noise=noise, latency_ms=latency_ms, seed=seed)
    ready = threading.Event()
    status: dict = {}

    def refused(cert, status):
        why = {
            "BadCertificateRevoked": f"revoked by its issuer's list in --crl {crl}",
            "BadCertificateRevocationUnknown": f"a revocation list of its issuer in --crl {crl} has expired since start",
            "BadCertificateUntrusted": f"not in --trust {trust}",
        }.get(status, f"checked against --trust {trust}")
        click.echo(f"{endpoint}: refused a client certificate {cert}: {status} ({why})", err=True)

    async def main():
        task = asyncio.create_task(
            lp.serve_machine(
                ms,
                sk.A_G,
                endpoint=endpoint,
                ready=ready,
                status=status,
                ack_timeout=ack_timeout,
                security=security,
                on_refused=refused,
            )
        )
        while not ready.is_set() and not task.done():
            await asyncio.sleep(0.01)
        if ready.is_set():
            click.echo(
                f"serving the skin testbed at {endpoint} (seed {seed}): target thickness {sk.T_TARGET} mm, "
                f"depth {sk.A_G} mm, {len(ms)} pockets, "
                + ("NoSecurity" if security is None else "Basic256Sha256 SignAndEncrypt")
                + (f", client certificates trusted from {trust}" if trust is not None else "")
                + (f", revocation lists from {crl}" if crl is not None else ""),
                err=True,
            )
        await task

    try:
        asyncio.run(main())
    except OSError as err:
        raise InputError(f"cannot serve: {err}", endpoint) from None
    if status.get("lost"):
        from ..errors import RefusedError

        raise RefusedError(
            "the client stopped acknowledging readings (watchdog, --ack-timeout): W1 held, feed "
            "stopped; the pockets are not finished"
        )
    if status.get("fault"):
        from ..errors import RefusedError

        raise RefusedError(
            "the client set Fault (its interlocks stopped the loop): W1 held, feed stopped; "
            "the pockets are not finished"
        )
    run = sk.result("opcua client", ms, [None] * len(ms), noise=noise, latency_ms=latency_ms, seed=seed)
    d = run.as_dict()
    d["endpoint"] = endpoint
    for key in ("fallbacks", "compensator_steps"):  # the client's to tell
        d.pop(key)
    summary(
        f"client: |error| at 2 × 13 checkpoints max {d['max_abs_error'] * 1000:.1f} µm, "
        f"min {d['min_abs_error'] * 1000:.1f} µm, mean {d['mean_abs_error'] * 1000:.1f} µm"
    )
    if json_path:
        write_json(json_path, d)


@skin.command("certs")
@click.argument("folder", type=click.Path(exists=True, file_okay=False, path_type=Path))
@click.option("--host", default="127.0.0.1", show_default=True, help="Host name in the certificates.")
@handle_errors(staged=False)
def certs(folder, host):
    """Make self-signed application certificates (one year) for the OPC UA exchange in FOLDER:
    controller.der/.pem (for `skin serve` or a test controller) and client.der/.pem (for `skin loop`);
    a valid existing pair is kept."""
    import asyncio

    from .. import loop as lp

    try:
        paths = asyncio.run(lp.make_certificates(folder, host))
    except OSError as e:
        raise InputError(f"cannot write the certificates: {e.strerror or e}", str(folder)) from None
    for name, (cert, key) in paths.items():
        summary(f"{name}: {cert} (certificate), {key} (private key)")
