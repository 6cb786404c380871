"""Registries of the models a config may name (the sky, the foreground, the ground's
reflectance): each name with the config keys only it takes and the class that makes it,
imported on first use, so that a config is checked without numpy and a new model is one
module and one line in ``vocabulary`` (docs/design.md, "Models plug in")."""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field

__all__ = ["Model", "Registry"]


@dataclass(frozen=True)
class Model:
    """One model of a registry.

    Attributes
    ----------
    name : str
        What a config calls it: the value of the registry's key.
    home : str
        ``"package.module:Class"``: the class in ``pipeline/package/module.py`` that makes it, imported when
        first asked for (``Registry.load``).
    keys : tuple of str
        The keys of its config section that only some models take, this one among them.
    numbers : dict
        Keys read as plain numbers for a model the parser has no code of its own for:
        {key: (default, least, most, unit)}; the values reach the model as
        ``params`` ((key, value), ...).
    """

    name: str
    home: str
    keys: tuple[str, ...] = ()
    numbers: dict = field(default_factory=dict, hash=False, compare=False)


class Registry:
    """The models of one config key.

    Parameters
    ----------
    key : str
        The config key that names a model, e.g. ``"sky.model"``.
    *models : Model
        Its models, in the order a message lists them.
    """

    def __init__(self, key: str, *models: Model):
        self.key = key
        self._models = {m.name: m for m in models}

    @property
    def names(self) -> tuple[str, ...]:
        """The names a config may give, in order.

        Returns
        -------
        tuple of str
        """
        return tuple(self._models)

    def __contains__(self, name) -> bool:
        return name in self._models

    def __getitem__(self, name: str) -> Model:
        return self._models[name]

    def owners(self, key: str) -> tuple[str, ...]:
        """The models that take config key ``key`` (among their ``keys`` or ``numbers``).

        Parameters
        ----------
        key : str
            A key of the model's config section.

        Returns
        -------
        tuple of str
            Their names; empty when every model, or none, takes it.
        """
        return tuple(m.name for m in self._models.values() if key in m.keys or key in m.numbers)

    def owned_keys(self) -> tuple[str, ...]:
        """Every key that only some models take, in the order the models give them.

        Returns
        -------
        tuple of str
        """
        return tuple(dict.fromkeys(k for m in self._models.values() for k in (*m.keys, *m.numbers)))

    def load(self, name: str) -> type:
        """The class that makes model ``name``, its module imported on first use.

        Parameters
        ----------
        name : str
            A name of this registry.

        Returns
        -------
        type
            The class named by the model's ``home``.
        """
        module, _, attribute = self._models[name].home.partition(":")
        return getattr(importlib.import_module(f"pipeline.{module}"), attribute)
