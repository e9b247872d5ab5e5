"""Checks of the names and URIs every command takes (each returns why a value is wrong, or None),
run before any store, folder or cache exists."""

from __future__ import annotations

#: The longest experiment name: MLflow's database column holds 256 characters (MLflow refuses more
#: than 500 with a traceback), and the name also enters tags and file names.
MAX_EXPERIMENT_NAME = 250


def experiment_problem(value: str) -> str | None:
    """Why ``value`` is no usable MLflow experiment name, or None.

    Example:
        >>> experiment_problem("vlmrl"), experiment_problem(""), experiment_problem(" x") is not None
        (None, 'an experiment needs a name; pass --experiment NAME', True)
        >>> experiment_problem("a\\tb").startswith("the experiment name 'a\\\\tb' holds a tab")
        True
    """
    if not value.strip():
        return "an experiment needs a name; pass --experiment NAME"
    if len(value) > MAX_EXPERIMENT_NAME:
        return (f"the experiment name is {len(value):,} characters long; MLflow stores at most {MAX_EXPERIMENT_NAME} "
                "here, pass a shorter --experiment")
    if not value.isprintable():
        return (f"the experiment name {value!r} holds a tab, newline or other control character; pass a name of "
                "printable characters")
    if value != value.strip():
        return f"'{value}' starts or ends with a space; pass the name without it"
    return None


def tracking_uri_problem(value: str | None) -> str | None:
    """Why ``value`` is no usable tracking URI (None, the default store, is fine), or None.

    Example:
        >>> tracking_uri_problem(None), tracking_uri_problem("sqlite:///m.db"), tracking_uri_problem(" ") is not None
        (None, None, True)
    """
    if value is not None and not value.strip():
        return ("the tracking URI is empty; pass sqlite:///PATH/mlflow.db or http://HOST:PORT, or leave it out for "
                "the default")
    return None
