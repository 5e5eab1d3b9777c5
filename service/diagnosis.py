"""Why a session could not connect to its router, told from outside Zenoh.

Zenoh reports every failure to connect the same way ("Unable to connect to any of [...]"):
nothing listening, a router certificate the client does not trust, a client certificate the
router refuses (mTLS) and a wrong user or password all read alike. :func:`connect_failure`
tries each ``tcp`` and ``tls`` endpoint of the configuration again, one step at a time (TCP,
the TLS handshake with the configuration's own certificates, the router's first answer), and
says which step failed. It reads the configuration only; nothing it learns is kept.

A session outlives its certificate: the router checks it at the handshake only, so a
certificate that expires while the process runs locks it out at its next connection (a router
restart, a lost link), and a fleet whose certificates were issued together goes dark together.
:func:`expiring_certificates` says ahead of time which of the configuration's certificates
expires soon.
"""

from __future__ import annotations

import base64
import datetime
import json
import os
import re
import socket
import ssl
import warnings

import zenoh

__all__ = ["EXPIRY_WARNING_DAYS", "connect_failure", "expiring_certificates", "split_endpoint",
           "unreadable_files"]

# days before a certificate's end from which a process says so (the development script renews
# a certificate with fewer days left than this)
EXPIRY_WARNING_DAYS = 30

TIMEOUT = 2.0  # seconds for each step of one endpoint's check
_TLS = "transport/link/tls/"
_TLS_FILES = ("root_ca_certificate", "connect_certificate", "connect_private_key")
# OpenSSL's verification results (X509_V_ERR_*) that another CA would not fix
_NOT_YET_VALID, _EXPIRED, _HOSTNAME_MISMATCH, _IP_ADDRESS_MISMATCH = 9, 10, 62, 64
_SCRIPT = "deploy/scripts/gen-dev-certs.sh"  # the development fleet's certificates
_MODULE = re.escape(__name__) + "$"  # this module's warnings (the filter of _quiet_loads)


def split_endpoint(endpoint: str) -> tuple[str, str, int] | None:
    """``(protocol, host, port)`` of a ``tcp`` or ``tls`` endpoint (``tls/host:port``,
    ``tcp/[::1]:7447``, with or without ``?``/``#`` metadata), else None."""
    protocol, _, address = endpoint.partition("/")
    if protocol not in ("tcp", "tls") or not address:
        return None
    address = address.split("?", 1)[0].split("#", 1)[0]
    host, _, port = address.rpartition(":")
    if not host or not port.isdigit():
        return None
    return protocol, host.strip("[]"), int(port)


def _value(conf: zenoh.Config, key: str):
    try:
        return json.loads(conf.get_json(key))
    except Exception:  # an unknown key in this Zenoh version
        return None


# the files a router's configuration names (its TLS identity, its clients' CA, the passwords)
_ROUTER_FILES = tuple(_TLS + name for name in ("listen_certificate", "listen_private_key",
                                               "root_ca_certificate")) + (
    "transport/auth/usrpwd/dictionary_file",)


def unreadable_files(conf: zenoh.Config) -> str | None:
    """The files a router's configuration names that this process cannot read, each with its
    setting and why (``"transport/link/tls/listen_private_key /etc/asnn/router.key: Permission
    denied"``, joined by ``"; "``), or None: Zenoh's own error names neither ("Invalid TLS
    private key file: No such file or directory")."""
    found = []
    for key in _ROUTER_FILES:
        path = _value(conf, key)
        if not isinstance(path, str) or not path:
            continue
        try:
            with open(path, "rb"):
                pass
        except OSError as exc:
            found.append(f"{key} {path}: {exc.strerror or exc}")
    return "; ".join(found) or None


# what an expired certificate of each kind does to the session that names it
_EXPIRED_MEANS = {
    "connect_certificate": "the router refuses this client at its next connection (a router "
                           "restart, a lost link)",
    "listen_certificate": "every client refuses this router at its next connection",
    "root_ca_certificate": "the certificates it signed are refused at the next connection",
}


def _quiet_loads() -> None:
    """Ignore the warnings of this module's certificate loads (cryptography warns at each load
    of a bundle's odd old CAs, a system bundle's serial numbers that are not positive: not this
    process's to say, at every check) by a filter of this module's own, added where it is
    missing. warnings.catch_warnings around the load swapped the process's filters from the
    router watch's thread, which is not thread-safe (every other thread's warnings ignored
    meanwhile, a filter another thread set meanwhile undone after); this adds one filter at
    most, and only reads them after. Not once at import: a catch_warnings block that the
    import came in drops the filter at its end."""
    for action, _, category, module, _ in warnings.filters:
        if (action == "ignore" and category is UserWarning and module is not None
                and module.pattern == _MODULE):
            return
    warnings.filterwarnings("ignore", category=UserWarning, module=_MODULE)


def _certificates(conf: zenoh.Config, name: str) -> tuple[str, list] | None:
    """The setting's label and the certificates it names (a file or inline base64 PEM), or None
    where it is not set, cannot be read, or holds none that cryptography parses (opening the
    session judges those), or cryptography is not installed."""
    try:
        from cryptography import x509
    except ImportError:
        return None
    path = _value(conf, _TLS + name)
    try:
        if isinstance(path, str) and path:
            with open(path, "rb") as fh:
                pem = fh.read(1 << 20)  # a certificate chain is a few kB, a CA bundle 200
            label = f"{name} {path}"
        else:
            inline = _value(conf, _TLS + name + "_base64")
            if not isinstance(inline, str) or not inline:
                return None
            pem = base64.b64decode(inline, validate=False)
            label = f"{name} (inline)"
        _quiet_loads()
        certificates = x509.load_pem_x509_certificates(pem)
    except Exception:  # OSError, ValueError, x509.InvalidVersion: not judged here
        return None
    return (label, certificates) if certificates else None


def _end(name: str, certificates: list, own: list | None) -> datetime.datetime:
    """When the setting's certificates stop serving: a chain (its own, the listening one) when
    its first ends; a trust bundle when the CA that issued this process's own certificate ends
    (without one, which CA signs the router's is not known: the latest end)."""
    if name != "root_ca_certificate":
        return min(c.not_valid_after_utc for c in certificates)
    issuers = [c for c in certificates if own and c.subject == own[0].issuer] or certificates
    return max(c.not_valid_after_utc for c in issuers)


def expiring_certificates(conf: zenoh.Config, now: datetime.datetime | None = None,
                          within_days: float = EXPIRY_WARNING_DAYS) -> str | None:
    """Which of the TLS certificates the configuration names (its own, the router's listening
    one, the CA that issued them; files or inline base64) have expired or expire within
    ``within_days`` days, and what that does to the session; None where none does. A file
    that cannot be read or parsed is not judged here (opening the session says so).

    Parameters
    ----------
    conf : zenoh.Config
        A client's or a router's configuration.
    now : datetime, optional
        The present, timezone-aware (default: the system clock's).
    within_days : float
        How far ahead to look.
    """
    now = now or datetime.datetime.now(datetime.timezone.utc)
    loaded = {name: _certificates(conf, name) for name in _EXPIRED_MEANS}
    own = next((loaded[n][1] for n in ("connect_certificate", "listen_certificate")
                if loaded[n]), None)
    found = []
    for name, means in _EXPIRED_MEANS.items():
        if loaded[name] is None:
            continue
        label, certificates = loaded[name]
        end = _end(name, certificates, own)
        left = end - now
        day = end.strftime("%Y-%m-%d %H:%M UTC")
        if left <= datetime.timedelta(0):
            found.append(f"{label} expired on {day}: {means}")
        elif left <= datetime.timedelta(days=within_days):
            found.append(f"{label} expires on {day}, in {left.days} days {left.seconds // 3600} "
                         f"hours: issue it again before then (the development fleet's: run "
                         f"{_SCRIPT} again); once expired, {means}")
    return "; ".join(found) or None


def _tls_context(conf: zenoh.Config) -> tuple[ssl.SSLContext, dict]:
    """The client's TLS context as the configuration describes it, and its files' paths by
    name (:data:`_TLS_FILES`; None where not set). Raises OSError or ssl.SSLError for a file
    that cannot be used."""
    files = {name: _value(conf, _TLS + name) for name in _TLS_FILES}
    for name, path in files.items():
        if path and not os.access(path, os.R_OK):
            raise OSError(f"{name} {path} cannot be read")
    context = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    if files["root_ca_certificate"]:
        context.load_verify_locations(files["root_ca_certificate"])
    else:
        context.load_default_certs()
    if _value(conf, _TLS + "verify_name_on_connect") is False:
        context.check_hostname = False
    if files["connect_certificate"]:
        context.load_cert_chain(files["connect_certificate"], files["connect_private_key"])
    return context, files


def _uses_base64(conf: zenoh.Config) -> bool:
    return any(_value(conf, _TLS + name + "_base64") for name in _TLS_FILES)


def _untrusted_router(exc: ssl.SSLCertVerificationError, host: str, ca: str | None) -> str:
    """Why the router's certificate failed verification, and the fix for that failure: an
    expired certificate or one issued for other names is not fixed by another CA."""
    why = f"({exc.verify_message})"
    if exc.verify_code in (_EXPIRED, _NOT_YET_VALID):
        return (f"the router's certificate is out of its validity {why}: check this machine's "
                f"clock, or issue the router's certificate again (the development fleet's: run "
                f"{_SCRIPT} again)")
    if exc.verify_code in (_HOSTNAME_MISMATCH, _IP_ADDRESS_MISMATCH):
        return (f"the router's certificate does not name {host} {why}: connect by a name it "
                f"holds, or issue it again naming {host} (the development fleet's: {_SCRIPT} "
                f"[--robots ...] [OUT_DIR] {host})")
    trusted = ca or "the system's CAs"
    return (f"the router's certificate is not trusted by {trusted} {why}: "
            "root_ca_certificate must be the CA that signed the router's certificate")


def _check_endpoint(conf: zenoh.Config, endpoint: str, timeout: float) -> str | None:
    parts = split_endpoint(endpoint)
    if parts is None:
        return None
    protocol, host, port = parts
    try:
        raw = socket.create_connection((host, port), timeout=timeout)
    except OSError as exc:
        return f"nothing accepts connections at {host}:{port} ({exc.strerror or exc})"
    with raw:
        if protocol == "tcp":
            return ("something accepts connections there, but the session was refused: "
                    "does the router speak TLS (tls/...), or ask for a user and password "
                    "(transport/auth/usrpwd)?")
        if _uses_base64(conf):
            return None  # certificates given inline: not checked here
        try:
            context, files = _tls_context(conf)
        except (OSError, ssl.SSLError) as exc:
            return f"this client's TLS files cannot be used: {exc}"
        certificate = files["connect_certificate"]
        try:
            tls = context.wrap_socket(raw, server_hostname=host)
        except ssl.SSLCertVerificationError as exc:
            return _untrusted_router(exc, host, files["root_ca_certificate"])
        except (ssl.SSLError, OSError) as exc:
            return f"the TLS handshake failed ({getattr(exc, 'reason', None) or exc})"
        with tls:
            tls.settimeout(timeout)
            try:
                tls.recv(1)  # the router speaks only after the client: an alert, or nothing
            except TimeoutError:
                pass
            except ssl.SSLError as exc:  # TLS 1.3: the client certificate is judged here
                if certificate is None:
                    return (f"the router requires a client certificate ({exc.reason}): set "
                            f"{_TLS}connect_certificate and connect_private_key (mTLS)")
                if "EXPIRED" in (exc.reason or ""):
                    return (f"the router refused this client's certificate {certificate} "
                            f"({exc.reason}): it has expired (or is not valid yet); issue it "
                            f"again (the development fleet's: run {_SCRIPT} again)")
                return (f"the router refused this client's certificate {certificate} "
                        f"({exc.reason}): it must be signed by the CA the router trusts")
            except OSError:
                pass
    user = _value(conf, "transport/auth/usrpwd/user")
    return ("TLS with this client's certificate works, but the router refused the session "
            + (f"after it: check the user {user!r} and its password (transport/auth/usrpwd)"
               if user else "after it: does it ask for a user and password "
               "(transport/auth/usrpwd)?"))


def connect_failure(conf: zenoh.Config, timeout: float = TIMEOUT) -> str | None:
    """What stops a session of ``conf`` from connecting to its ``connect/endpoints``, one
    clause per ``tcp`` or ``tls`` endpoint checked (``"ENDPOINT: why"``, joined by ``"; "``),
    or None where none could be checked.

    Parameters
    ----------
    conf : zenoh.Config
        The configuration the session was opened with.
    timeout : float
        Seconds each step may take (connecting, the handshake, the router's answer).
    """
    endpoints = _value(conf, "connect/endpoints") or []
    if isinstance(endpoints, dict):  # endpoints per mode
        endpoints = endpoints.get(_value(conf, "mode") or "peer", [])
    reasons = []
    for endpoint in endpoints:
        if not isinstance(endpoint, str):
            continue
        reason = _check_endpoint(conf, endpoint, timeout)
        if reason:
            reasons.append(f"{endpoint}: {reason}")
    return "; ".join(reasons) or None
