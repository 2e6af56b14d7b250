"""The matching stages, one module each (see docs/DESIGN.md for the data flow).

``observations`` merges a stopped car's fixes into one observation; ``candidates`` finds the
road positions near each (one R-tree query); ``selection`` leaves out outliers; ``emission``,
``routes`` and ``transition`` score the hidden Markov model; ``trellis`` builds and solves it
(Viterbi and forward-backward in ``viterbi``), repairing breaks; ``assemble`` turns the
solution into driven edges and per-fix positions, and ``loops`` takes out the loops and spurs
the fixes do not support. :func:`mapmatch.match` is the facade over them.
"""
