"""Named parameter blocks: the currency of models, fits and results.

A parameter set is a plain ``dict[str, np.ndarray]`` (block name → array of fixed shape).
Effects switch on by the presence of their blocks. This module packs and unpacks such
dicts to the flat vectors an optimiser wants, with a mask of which elements are free,
and names each scalar element (``'M[1][2]'``, ``'b[0]'``, ``'tau_s'``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

Params = dict[str, np.ndarray]


def as_params(blocks: Mapping[str, object]) -> Params:
    """Copy ``blocks`` into float arrays (scalars become 0-d arrays)."""
    return {k: np.array(v, dtype=float) for k, v in blocks.items()}


def element_names(name: str, shape: tuple[int, ...]) -> list[str]:
    """Scalar names of a block: ``b`` → ``b[0]``…, ``M`` → ``M[0][0]``…, scalar → ``name``."""
    if shape == ():
        return [name]
    return [name + "".join(f"[{i}]" for i in idx) for idx in np.ndindex(*shape)]


@dataclass
class Packer:
    """Maps a params dict (with a free mask) to and from a flat vector of free elements."""

    template: Params
    free: dict[str, np.ndarray]  # bool arrays, same shapes

    @classmethod
    def build(cls, template: Mapping[str, object], free: Mapping[str, object] | None = None) -> Packer:
        tpl = as_params(template)
        mask: dict[str, np.ndarray] = {}
        for name, value in tpl.items():
            spec = True if free is None else free.get(name, False)
            mask[name] = np.broadcast_to(np.asarray(spec, dtype=bool), value.shape).copy()
        return cls(tpl, mask)

    @property
    def names(self) -> list[str]:
        out: list[str] = []
        for name, value in self.template.items():
            elems = element_names(name, value.shape)
            out += [e for e, f in zip(elems, self.free[name].ravel()) if f]
        return out

    @property
    def size(self) -> int:
        return int(sum(m.sum() for m in self.free.values()))

    def pack(self, params: Mapping[str, np.ndarray]) -> np.ndarray:
        parts = [np.asarray(params[n], dtype=float)[self.free[n]].ravel() for n in self.template]
        return np.concatenate(parts) if parts else np.zeros(0)

    def unpack(self, x: np.ndarray) -> Params:
        out: Params = {}
        i = 0
        for name, value in self.template.items():
            block = value.copy()
            k = int(self.free[name].sum())
            if k:
                block[self.free[name]] = x[i : i + k]
                i += k
            out[name] = block
        return out

    def unpack_sigma(self, sigma_free: np.ndarray) -> Params:
        """Per-block 1-sigma arrays: the free elements' sigma, 0 for fixed elements."""
        out: Params = {}
        i = 0
        for name, value in self.template.items():
            block = np.zeros_like(value)
            k = int(self.free[name].sum())
            if k:
                block[self.free[name]] = sigma_free[i : i + k]
                i += k
            out[name] = block
        return out
