"""The named choices a user picks from (an architecture, a method, a controller, ...), in one
module that imports nothing: the command line lists them in ``--help`` without loading the
simulator or torch, and the library modules that check them import them from here.

>>> "cuda" in ARCHS and "diffusebot" in DESIGN_METHODS
True
"""

ARCHS = ("auto", "cpu", "cuda")  # Taichi back ends (dbtool.sim.runtime.init)
CONTROLLERS = ("prescribed", "none", "design")  # `dbtool simulate --controller`
DESIGN_METHODS = ("diffusebot", "particle")  # `dbtool design --method`
RECONSTRUCTIONS = ("dpsr", "direct_sdf")  # `dbtool robotize --method` (docs/robotize.md)
STIFFNESS = ("constant", "depth")  # stiffness mappings of the robotizer
PRIOR_MODELS = ("base", "upsampler")  # `dbtool prior train --kind`
PRIOR_VERSION = 1  # the shipped prior sampled by default (docs/prior.md)

# the comparison's methods (docs/results.md, docs/method.md §7)
GRADIENT = ("particle", "voxel", "implicit", "cppn")
METHODS = (*GRADIENT, "prior", "diffusebot")  # the table of docs/results.md (``--method all``)
ABLATION = ("embedding", "codesign", "diffusebot-paper")  # DiffuseBot's parts, on request
KNOWN = (*METHODS, *ABLATION)
