"""dbtool: breeding soft robots with physics-augmented generative diffusion (DiffuseBot).

The scripting entry points (:mod:`dbtool.api`, docs/python.md) load on first use, so that
``import dbtool`` stays light:

>>> import dbtool
>>> dbtool.get_task("crawling").title
'Crawling'
"""

__version__ = "0.1.0"

API = ("get_task", "reference_body", "load_design", "simulate", "run_design", "export_design",
       "run_comparison")
__all__ = ["__version__", *API]


def __getattr__(name: str):
    if name in API:
        from dbtool import api

        return getattr(api, name)
    raise AttributeError(f"module 'dbtool' has no attribute {name!r}")
