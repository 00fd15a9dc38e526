"""``none``: nothing missing; the measurement is the nominal model."""

from simhw.effects import Effect

EFFECT = Effect("none", "no effect", (), lambda cfg, axis: cfg)
