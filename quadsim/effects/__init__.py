"""Unmodelled physical effects, one module each, behind one interface (:mod:`.base`)."""

from .base import Effect, EffectBase, EffectContext, EffectLoads, EffectParameter, EffectSet

__all__ = ["Effect", "EffectBase", "EffectContext", "EffectLoads", "EffectParameter", "EffectSet"]
