from __future__ import annotations

import os
import subprocess
import sys

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vlmrl_cli.core import numeric_pin as pin

_VALUES = st.dictionaries(st.sampled_from(sorted(pin.PIN)), st.sampled_from(["AVX512", "avx512", "AUTO", "SSE41"]))


@given(_VALUES)
def test_a_user_setting_wins_and_the_rest_take_the_pin(user: dict[str, str]) -> None:
    env = pin.pinned_environ(user)
    for key, value in pin.PIN.items():
        assert env[key] == user.get(key, value)
    assert set(pin.user_set(env)) == set(user)


@given(_VALUES)
def test_applying_twice_changes_nothing_and_keeps_the_users_list(user: dict[str, str]) -> None:
    once = pin.pinned_environ(user)
    assert pin.pinned_environ(once) == once  # a child process re-applying it keeps the parent's record


@given(st.dictionaries(st.text("ABCXYZ_", min_size=1), st.text(max_size=4)), _VALUES)
def test_unpinning_removes_exactly_what_pinning_and_the_user_added(other: dict[str, str], user: dict[str, str]) -> None:
    env = other | user
    assert pin.unpinned_environ(pin.pinned_environ(env)) == other
    assert not set(pin.unpinned_environ(pin.pinned_environ(env))) & set(pin.PIN_VARIABLES)


def test_the_state_is_pinned_only_on_the_pins_values() -> None:
    assert pin.pin_state(pin.pinned_environ({})).pinned
    assert not pin.pin_state(pin.pinned_environ({"MKL_CBWR": "AVX2"})).pinned
    # a user who sets a variable to the pin's own value stays on the path and is not warned
    same = pin.pin_state(pin.pinned_environ({"MKL_CBWR": "COMPATIBLE"}))
    assert same.pinned and same.warning() is None


def test_a_user_override_is_warned_about_once_and_recorded() -> None:
    env: dict[str, str] = {"MKL_CBWR": "AVX2"}
    first = pin.apply(env)
    message = first.warning()
    assert message is not None and "MKL_CBWR=AVX2" in message and "MKL_CBWR=COMPATIBLE" in message
    record = pin.pin_record(env)
    assert record["pin"] == "unpinned" and record["pin.user"] == "MKL_CBWR=AVX2"
    assert "MKL_CBWR=AVX2" in record["pin.env"]


def test_a_library_loaded_before_the_pin_is_named_in_the_warning() -> None:
    state = pin.PinState(values=dict(pin.PIN), user={}, loaded_before=("torch",))
    assert not state.pinned
    assert "torch loaded before" in str(state.warning())


def test_the_cli_warns_once_on_stderr_and_its_workers_inherit_silently() -> None:
    env = {k: v for k, v in os.environ.items() if k not in (*pin.PIN, pin.USER_MARK, pin.APPLIED_MARK)}
    code = ("from vlmrl_cli.core.numeric_pin import apply; import subprocess, sys; apply(); "
            "subprocess.run([sys.executable, '-c', 'from vlmrl_cli.core.numeric_pin import apply; apply()'])")
    out = subprocess.run([sys.executable, "-c", code], env=env | {"ATEN_CPU_CAPABILITY": "default"},
                         capture_output=True, text=True, check=True, timeout=60)
    assert out.stderr.count("warning:") == 1 and "ATEN_CPU_CAPABILITY=default" in out.stderr


def test_the_entry_point_pins_before_torch_loads() -> None:
    env = {k: v for k, v in os.environ.items() if k not in (*pin.PIN, pin.USER_MARK, pin.APPLIED_MARK)}
    code = ("import sys; sys.argv = ['vlmrl', '--help']\n"
            "from vlmrl_cli.cli import entry\n"
            "try:\n    entry.main()\nexcept SystemExit:\n    pass\n"
            "import torch, os; print(torch.backends.cpu.get_cpu_capability(), os.environ['MKL_CBWR'])")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True,
                         timeout=120)
    assert out.stdout.strip().splitlines()[-1] == "AVX2 COMPATIBLE"


_NAMES = st.text(alphabet=st.characters(blacklist_categories=("Cc", "Cs", "Zl", "Zp"), blacklist_characters=":"),
                 min_size=1).filter(str.strip)


@given(_NAMES, st.integers(0, 255), st.integers(0, 255))
def test_a_cpu_is_named_with_its_family_and_model(name: str, family: int, model: int) -> None:
    text = f"vendor_id\t: GenuineIntel\ncpu family\t: {family}\nmodel\t\t: {model}\nmodel name\t: {name}\n\n"
    assert pin.describe_cpuinfo(text) == f"{name.strip()} (GenuineIntel family {family} model {model})"
    assert pin.describe_cpuinfo(text + "model name\t: another CPU\n") == pin.describe_cpuinfo(text)  # the first one


def test_this_machines_cpu_is_named() -> None:
    assert pin.cpu_model() not in ("", "unknown")


@given(st.sampled_from(pin.MKL_CBWR_BRANCHES), st.booleans(), st.booleans())
def test_every_documented_mkl_cbwr_value_is_known(branch: str, strict: bool, lower: bool) -> None:
    value = branch + (",STRICT" if strict else "")
    assert pin.mkl_knows(value.lower() if lower else value)
    assert not pin.mkl_knows(value + "X") and not pin.mkl_knows(f"{branch},FAST")


def test_an_mkl_cbwr_value_mkl_does_not_know_is_said_in_the_one_warning_line(
    capsys: pytest.CaptureFixture[str]
) -> None:
    env: dict[str, str] = {"MKL_CBWR": "garbage"}
    pin.apply(env)  # the entry point's call, on a copy of the environment
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("warning: ")
    assert "MKL_CBWR=garbage is not a value MKL knows (it takes one of AUTO, COMPATIBLE, SSE2" in lines[0]
    assert "AVX512_E4, optionally with ,STRICT" in lines[0] and "replaces vlmrl's numeric pin" in lines[0]
    assert pin.pin_record(env)["pin"] == "unpinned"
    for known in ("AVX2", "AVX512_E1,STRICT"):
        message = pin.pin_state(pin.pinned_environ({"MKL_CBWR": known})).warning()
        assert message is not None and "not a value MKL knows" not in message


@pytest.mark.parametrize(("variable", "library"), [("ATEN_CPU_CAPABILITY", "torch"), ("ONEDNN_MAX_CPU_ISA", "oneDNN")])
def test_a_torch_or_onednn_value_they_do_not_know_is_said_in_the_one_warning_line(
    capsys: pytest.CaptureFixture[str], variable: str, library: str
) -> None:
    # both were unchecked: a typo left the library to pick kernels by CPU, without a word (issue 50)
    env: dict[str, str] = {variable: "garbage"}
    pin.apply(env)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("warning: ")
    assert f"{variable}=garbage is not a value {library} knows (it takes one of " in lines[0]
    for known in ("avx512", "default") if variable == "ATEN_CPU_CAPABILITY" else ("AVX512_CORE", "avx2", "ALL"):
        message = pin.pin_state(pin.pinned_environ({variable: known})).warning()
        assert message is not None and "not a value" not in message
