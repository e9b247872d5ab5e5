"""The numeric pin: the kernel choices vlmrl fixes before torch loads, so that every x86-64-v3 CPU
computes the same numbers. Applied at the edges (``apply()``), never on import; a variable the user
set wins and is warned about once. See docs/development.md, "Same numbers on every x86-64 CPU"."""

from __future__ import annotations

import os
import platform
import sys
from collections.abc import Mapping, MutableMapping
from dataclasses import dataclass, replace
from pathlib import Path

#: The name of the numeric path, recorded with every run (bump it when ``PIN`` changes).
PIN_ID = "x86-64-v3/1"
PIN: Mapping[str, str] = {
    "MKL_CBWR": "COMPATIBLE",
    "ATEN_CPU_CAPABILITY": "avx2",
    "ONEDNN_MAX_CPU_ISA": "AVX2",
}
#: Set by ``apply``: the pin variables the user had set (comma-separated), for child processes.
USER_MARK = "VLMRL_PIN_USER"
#: Set by ``apply``: the pin's id, so that a child knows its parent applied it.
APPLIED_MARK = "VLMRL_PIN"
#: Every variable the pin sets in a process's environment: its own and its two marks.
PIN_VARIABLES: tuple[str, ...] = (*PIN, USER_MARK, APPLIED_MARK)
#: MKL_CBWR's branches as Intel documents them (oneMKL developer guide, "Specifying Code
#: Branches"); each may be followed by ``,STRICT``.
MKL_CBWR_BRANCHES: tuple[str, ...] = (
    "AUTO", "COMPATIBLE", "SSE2", "SSSE3", "SSE4_1", "SSE4_2", "AVX", "AVX2", "AVX512", "AVX512_MIC",
    "AVX512_E1", "AVX2_E1", "AVX512_MIC_E1", "AVX512_E2", "AVX512_E3", "AVX512_E4",
)
#: ATEN_CPU_CAPABILITY's values as torch reads them (``ATen/native/DispatchStub.cpp``: compared
#: exactly, in lower case, per platform; anything else is ignored with a warning and the CPU decides).
ATEN_CAPABILITIES: tuple[str, ...] = ("default", "avx2", "avx512", "vsx", "zvector", "sve256")
#: ONEDNN_MAX_CPU_ISA's values as oneDNN documents them ("CPU Dispatcher Control"; v2 to v3.x, the
#: AVX10 names from 3.5); anything else leaves oneDNN to pick by CPU.
ONEDNN_ISAS: tuple[str, ...] = (
    "ALL", "SSE41", "AVX", "AVX2", "AVX2_VNNI", "AVX2_VNNI_2", "AVX512_MIC", "AVX512_MIC_4OPS", "AVX512_CORE",
    "AVX512_CORE_VNNI", "AVX512_CORE_BF16", "AVX512_CORE_FP16", "AVX512_CORE_AMX", "AVX512_CORE_AMX_FP16",
    "AVX10_1_512", "AVX10_1_512_AMX", "AVX10_1_512_AMX_FP16", "AVX10_2_512", "AVX10_2_512_AMX_2",
)
#: Libraries whose presence in ``sys.modules`` means the pin may come too late for this process
#: (numpy is not pinned, so an earlier numpy import does not matter).
_NUMERIC_MODULES = ("torch",)


@dataclass(frozen=True)
class PinState:
    """What ``apply`` did: the values in force, the user's own (which win), libraries loaded before it."""

    values: Mapping[str, str]
    user: Mapping[str, str]
    loaded_before: tuple[str, ...] = ()

    @property
    def pinned(self) -> bool:
        """Whether every variable is at the pin's value and no library loaded before it was set."""
        return not self.loaded_before and all(self.values.get(k) == v for k, v in PIN.items())

    def warning(self) -> str | None:
        """One line about a user setting that moves the process off the pinned path, or None."""
        parts = []
        off = {k: v for k, v in self.user.items() if v != PIN[k]}
        if off:
            given = ", ".join(f"{k}={v}" for k, v in sorted(off.items()))
            ours = ", ".join(f"{k}={PIN[k]}" for k in sorted(off))
            parts.append(f"your {given} replaces vlmrl's numeric pin ({ours})")
        for key, value in sorted(off.items()):  # a typo the library would not take, so the CPU picks
            unknown = unknown_value(key, value)
            if unknown:
                parts.append(unknown)
        if self.loaded_before:
            parts.append(f"{' and '.join(self.loaded_before)} loaded before vlmrl could pin its kernels")
        if not parts:
            return None
        return ("warning: " + "; ".join(parts) + ": runs record it (vlmrl.pin.*), and their numbers may differ "
                "from the committed ones on other CPUs.")


def mkl_knows(value: str) -> bool:
    """Whether ``value`` is a documented ``MKL_CBWR`` setting (a branch, optionally ``,STRICT``)."""
    branch, comma, rest = value.partition(",")
    return branch.strip().upper() in MKL_CBWR_BRANCHES and (not comma or rest.strip().upper() == "STRICT")


def unknown_value(key: str, value: str) -> str | None:
    """Why ``value`` of pin variable ``key`` is one its library ignores (picking by CPU), or None.

    Example:
        >>> unknown_value("ATEN_CPU_CAPABILITY", "avx512") is None, unknown_value("ONEDNN_MAX_CPU_ISA", "avx2") is None
        (True, True)
        >>> unknown_value("ATEN_CPU_CAPABILITY", "garbage")[:56]
        'ATEN_CPU_CAPABILITY=garbage is not a value torch knows ('
    """
    if key == "MKL_CBWR" and not mkl_knows(value):
        return (f"MKL_CBWR={value} is not a value MKL knows (it takes one of {', '.join(MKL_CBWR_BRANCHES)}, "
                "optionally with ,STRICT)")
    if key == "ATEN_CPU_CAPABILITY" and value not in ATEN_CAPABILITIES:
        return (f"ATEN_CPU_CAPABILITY={value} is not a value torch knows (it takes one of "
                f"{', '.join(ATEN_CAPABILITIES)})")
    if key == "ONEDNN_MAX_CPU_ISA" and value.strip().upper() not in ONEDNN_ISAS:
        return f"ONEDNN_MAX_CPU_ISA={value} is not a value oneDNN knows (it takes one of {', '.join(ONEDNN_ISAS)})"
    return None


def pinned_environ(environ: Mapping[str, str]) -> dict[str, str]:
    """``environ`` with every pin variable the user left unset at the pin's value (pure)."""
    out = dict(environ)
    already = APPLIED_MARK in environ  # a parent applied it: its user list stands
    user = user_set(environ) if already else [k for k in PIN if k in environ]
    for key, value in PIN.items():
        out.setdefault(key, value)
    out[USER_MARK] = ",".join(user)
    out[APPLIED_MARK] = PIN_ID
    return out


def unpinned_environ(environ: Mapping[str, str]) -> dict[str, str]:
    """``environ`` without any pin variable or mark, as if ``apply`` had never run (pure)."""
    return {k: v for k, v in environ.items() if k not in PIN_VARIABLES}


def user_set(environ: Mapping[str, str]) -> list[str]:
    """The pin variables the user set, as recorded by the ``apply`` of this process or a parent."""
    return [k for k in environ.get(USER_MARK, "").split(",") if k in PIN]


def pin_state(environ: Mapping[str, str] | None = None) -> PinState:
    """The pin as it stands in ``environ`` (default: this process's), without changing anything."""
    env = os.environ if environ is None else environ
    values = {k: env.get(k, "unset") for k in PIN}
    user = {k: env[k] for k in user_set(env) if k in env}
    if APPLIED_MARK not in env:  # never applied: whatever is set is the user's
        user = {k: env[k] for k in PIN if k in env}
    return PinState(values=values, user=user)


def apply(environ: MutableMapping[str, str] | None = None, *, warn: bool = True) -> PinState:
    """Pin the kernels of this process and its children (call it before torch or numpy load); warns
    once on stderr, where the pin is first applied, when a user's variable moves it off the pin."""
    env = os.environ if environ is None else environ
    first = APPLIED_MARK not in env
    loaded = tuple(m for m in _NUMERIC_MODULES if m in sys.modules) if environ is None else ()
    new = pinned_environ(env)
    for key in PIN_VARIABLES:
        env[key] = new[key]
    state = replace(pin_state(env), loaded_before=loaded if first else ())
    message = state.warning()
    if warn and first and message is not None:
        print(message, file=sys.stderr)
    return state


def cpu_model() -> str:
    """The CPU's model name with vendor, family, model and stepping (a hypervisor may show only
    ``AMD EPYC``; the family tells Zen 3/4 from Zen 5), else the platform's processor string."""
    return describe_cpuinfo(read_cpuinfo()) or platform.processor() or platform.machine() or "unknown"


def read_cpuinfo(path: str = "/proc/cpuinfo") -> str:
    """The text of ``/proc/cpuinfo`` ("" where it cannot be read)."""
    try:
        return Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError:
        return ""


def cpuinfo_fields(text: str) -> dict[str, str]:
    r"""The first processor's ``key: value`` fields of a ``/proc/cpuinfo`` text (pure).

    Example:
        >>> cpuinfo_fields("model name\t: AMD EPYC\nflags\t\t: fpu avx2\n\nmodel name\t: other\n")
        {'model name': 'AMD EPYC', 'flags': 'fpu avx2'}
    """
    fields: dict[str, str] = {}
    for line in text.split("\n\n", 1)[0].splitlines():
        key, sep, value = line.partition(":")
        if sep:
            fields.setdefault(key.strip(), value.strip())
    return fields


def describe_cpuinfo(text: str) -> str | None:
    r"""The first processor of a ``/proc/cpuinfo`` text in one line, or None when it names no model (pure)."""
    fields = cpuinfo_fields(text)
    name = fields.get("model name")
    if not name:
        return None
    ident = " ".join(f"{label}{fields[key]}" for key, label in
                     (("vendor_id", ""), ("cpu family", "family "), ("model", "model "), ("stepping", "stepping "))
                     if fields.get(key))
    return f"{name} ({ident})" if ident else name


def pin_record(environ: Mapping[str, str] | None = None) -> dict[str, str]:
    """The numeric path of a run, tagged ``vlmrl.<key>``: ``pin`` (id, or ``unpinned``), ``pin.env``,
    ``pin.user`` and ``cpu.model``.
    """
    state = pin_state(environ)
    return {
        "pin": PIN_ID if state.pinned else "unpinned",
        "pin.env": " ".join(f"{k}={state.values[k]}" for k in sorted(PIN)),
        "pin.user": ",".join(f"{k}={v}" for k, v in sorted(state.user.items())) or "none",
        "cpu.model": cpu_model(),
    }
