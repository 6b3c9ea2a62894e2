"""``dbtool view``'s views of the kinds of folder (docs/viewing.md): a design run's buffer and
co-design trajectory, an export folder's parts with a cut plane, a comparison's robots.

They sit above the parts they show (co-design, robotizer, export, comparison); the viewer's
common pieces (server, task scene, colours) are :mod:`dbtool.viz.viewer`.
"""
