"""One numeric path on every x86-64-v3 CPU: the kernel choices vlmrl pins before torch loads.

Torch's BLAS (Intel MKL) picks its sgemm kernels by CPU model, so plain PPO trained other
agents on a Sapphire Rapids machine than on AMD EPYC and Ice Lake ones (docs/development.md,
"Same numbers on every x86-64 CPU"). The variables below fix each library's choice to one that
every CPU from x86-64-v3 (AVX2 + FMA) up runs the same way:

* ``MKL_CBWR=COMPATIBLE``: MKL's conditional-numerical-reproducibility branch built on SSE2
  without the CPU-specific ``rcpps``/``rsqrtps``. Intel documents its other branches (``AVX2``,
  ``AVX512``) as reproducible across *Intel* CPUs only: on other CPUs they fall back to ``AUTO``,
  which picks by CPU again (on an AMD EPYC, ``AVX2``, ``AVX512`` and ``AVX512_E1`` trained one
  agent and ``COMPATIBLE`` another).
* ``ATEN_CPU_CAPABILITY=avx2``: torch's own vectorised kernels (reductions, ``exp``, ``tanh``,
  Adam's updates) at one vector width, whether or not the CPU has AVX-512.
* ``ONEDNN_MAX_CPU_ISA=AVX2``: oneDNN's JIT kernels at that width too (not on PPO's path as
  measured, pinned so that a torch that routes an op through it cannot pick by CPU).

numpy's SIMD dispatch and OpenBLAS are not pinned: measured, neither is on a training path
(``NPY_DISABLE_CPU_FEATURES`` and ``OPENBLAS_CORETYPE`` leave every pinned digest unchanged,
``tests/training/test_cpu_paths.py``), and a disabled feature that a numpy build does not
dispatch stops numpy from importing at all.

The pin only works in a process whose libraries have not loaded yet, so it is applied at the
edges, never on import: the ``vlmrl`` command, ``python -m vlmrl_cli``, the test suite's
conftest, the scripts and benchmarks call ``apply()`` first; sweep workers inherit it (local
workers fork from a fork server that the pinned process starts, and take over its environment;
``vlmrl verify``'s spawned processes copy it; Ray workers get it through their ``runtime_env``). A variable
the user set wins, is warned about once (``VLMRL_PIN_USER`` tells child processes which ones
were the user's), and every run records the values in force (``pin_record``).
"""

from __future__ import annotations

import os
import platform
import sys
from collections.abc import Mapping, MutableMapping
from dataclasses import dataclass
from pathlib import Path

#: The name of the numeric path, recorded with every run (bump it when ``PIN`` changes).
PIN_ID = "x86-64-v3/1"
#: The oldest CPU on which the pin gives the committed numbers.
OLDEST_CPU = "x86-64-v3 (AVX2 + FMA: Intel Haswell, AMD Zen and later)"
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
    """What ``apply`` did: the values in force for each pin variable, the ones the user set
    (name -> their value, which wins), and the numeric libraries already loaded before it."""

    values: Mapping[str, str]
    user: Mapping[str, str]
    loaded_before: tuple[str, ...] = ()

    @property
    def pinned(self) -> bool:
        """Whether this process computes on the pinned path: every variable at the pin's value
        and none of the libraries loaded before it was set."""
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
    """Whether ``value`` is an ``MKL_CBWR`` setting Intel documents: a branch of
    ``MKL_CBWR_BRANCHES``, optionally followed by ``,STRICT`` (case aside).

    Example:
        >>> mkl_knows("AVX2"), mkl_knows("avx512_e1,STRICT"), mkl_knows("garbage"), mkl_knows("AVX2,FAST")
        (True, True, False, False)
    """
    branch, comma, rest = value.partition(",")
    return branch.strip().upper() in MKL_CBWR_BRANCHES and (not comma or rest.strip().upper() == "STRICT")


def unknown_value(key: str, value: str) -> str | None:
    """Why ``value`` of pin variable ``key`` is not one its library knows (it would ignore it and
    pick kernels by CPU), or None when it knows it.

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
    """``environ`` with every pin variable the user left unset at the pin's value (pure).

    Example:
        >>> env = pinned_environ({"MKL_CBWR": "AVX2"})
        >>> env["MKL_CBWR"], env["ATEN_CPU_CAPABILITY"], env[USER_MARK]
        ('AVX2', 'avx2', 'MKL_CBWR')
    """
    out = dict(environ)
    already = APPLIED_MARK in environ  # a parent applied it: its user list stands
    user = user_set(environ) if already else [k for k in PIN if k in environ]
    for key, value in PIN.items():
        out.setdefault(key, value)
    out[USER_MARK] = ",".join(user)
    out[APPLIED_MARK] = PIN_ID
    return out


def unpinned_environ(environ: Mapping[str, str]) -> dict[str, str]:
    """``environ`` without the pin: none of its variables or marks, as if ``apply`` had never run
    and the user had set none of them (pure; a fresh process started with it computes on whatever
    path its libraries pick for the CPU).

    Example:
        >>> unpinned_environ(pinned_environ({"HOME": "/root", "MKL_CBWR": "AVX2"}))
        {'HOME': '/root'}
    """
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
    """Pin the kernels of this process and of every process it starts (call it before anything
    imports torch or numpy). Keeps a variable the user set, and prints one warning line to
    stderr when that moves the process off the pin (not again in child processes: ``warn``
    is only honoured where the pin is applied first)."""
    env = os.environ if environ is None else environ
    first = APPLIED_MARK not in env
    loaded = tuple(m for m in _NUMERIC_MODULES if m in sys.modules) if environ is None else ()
    new = pinned_environ(env)
    for key in PIN_VARIABLES:
        env[key] = new[key]
    state = pin_state(env)
    state = PinState(values=state.values, user=state.user, loaded_before=loaded if first else ())
    message = state.warning()
    if warn and first and message is not None:
        print(message, file=sys.stderr)
    return state


def cpu_model() -> str:
    """The CPU's model name with its vendor, family, model and stepping (``/proc/cpuinfo``), or
    the platform's processor string: a hypervisor may show only ``AMD EPYC`` as the name, which
    the family tells apart (25 is Zen 3/4, 26 is Zen 5)."""
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
    r"""The first processor of a ``/proc/cpuinfo`` text in one line, or None when it names no model (pure).

    Example:
        >>> describe_cpuinfo("vendor_id\t: AuthenticAMD\ncpu family\t: 26\nmodel\t\t: 2\n"
        ...                  "model name\t: AMD EPYC\nstepping\t: 1\n\nvendor_id\t: AuthenticAMD\n")
        'AMD EPYC (AuthenticAMD family 26 model 2 stepping 1)'
        >>> describe_cpuinfo("model name : Intel Xeon"), describe_cpuinfo("flags : avx2")
        ('Intel Xeon', None)
    """
    fields = cpuinfo_fields(text)
    name = fields.get("model name")
    if not name:
        return None
    ident = " ".join(f"{label}{fields[key]}" for key, label in
                     (("vendor_id", ""), ("cpu family", "family "), ("model", "model "), ("stepping", "stepping "))
                     if fields.get(key))
    return f"{name} ({ident})" if ident else name


def pin_record(environ: Mapping[str, str] | None = None) -> dict[str, str]:
    """What names the numeric path of a run (the tracking layer tags it as ``vlmrl.<key>``):
    ``pin``, the pin's id (``unpinned`` when a pin variable is off its value); ``pin.env``, the
    values in force; ``pin.user``, the user's settings; ``cpu.model``, the CPU.

    Example:
        >>> record = pin_record(pinned_environ({}))
        >>> record["pin"], record["pin.env"], record["pin.user"]
        ('x86-64-v3/1', 'ATEN_CPU_CAPABILITY=avx2 MKL_CBWR=COMPATIBLE ONEDNN_MAX_CPU_ISA=AVX2', 'none')
    """
    state = pin_state(environ)
    on_pin = all(state.values.get(k) == v for k, v in PIN.items())
    return {
        "pin": PIN_ID if on_pin else "unpinned",
        "pin.env": " ".join(f"{k}={state.values[k]}" for k in sorted(PIN)),
        "pin.user": ",".join(f"{k}={v}" for k, v in sorted(state.user.items())) or "none",
        "cpu.model": cpu_model(),
    }
