"""Human steering models: features, the ARX description, models, fitting."""

from hasa_env.steering.arx import ARXForm

__all__ = ["ARXForm"]
