"""Options objects: a frozen dataclass of settings, and today's keywords over it.

The package's entry points take their settings as one frozen dataclass (``options=``) and
still take each setting as a keyword, which overrides the object's field
(:class:`~bayesplate.sampling.options.ChainOptions`,
:class:`~bayesplate.reduced.options.FastModelOptions`,
:class:`~bayesplate.estimators.options.EstimatorOptions`,
:class:`~bayesplate.discrepancy.search.options.DiagnoseOptions`). :func:`with_overrides` is
their one rule: an unknown keyword is a :class:`TypeError` naming the function, as Python's
own would be.
"""

from __future__ import annotations

from dataclasses import fields, replace

__all__ = ["with_overrides"]


def with_overrides(cls, options, caller, overrides):
    """`options` (default: ``cls()``) with `overrides`, each the name of one of its fields.

    Parameters
    ----------
    cls : type
        A frozen dataclass.
    options : cls or None
    caller : str
        The entry point's name, for the messages.
    overrides : dict
        Field name to value.

    Returns
    -------
    cls
        `options` itself when there is nothing to override.

    Raises
    ------
    TypeError
        An override that is no field of `cls`, or `options` of another type.
    """
    unknown = sorted(set(overrides) - {f.name for f in fields(cls)})
    if unknown:
        raise TypeError(f"{caller}() got unexpected keyword argument(s) {', '.join(unknown)}")
    if options is None:
        return cls(**overrides)
    if not isinstance(options, cls):
        raise TypeError(f"{caller}(): options must be a {cls.__name__}, not {type(options)}")
    return replace(options, **overrides) if overrides else options
