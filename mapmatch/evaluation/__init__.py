"""Measuring the matcher: simulated trips with ground truth, scoring, benchmarks.

``simulate`` drives trips on a real network and observes them (noise, stops, outages,
canyons); ``scoring`` scores a match against its truth (route mismatch, length error, U-turns,
loops, verdicts); ``benchmark`` and ``accuracy`` run the speed and accuracy benchmarks behind
``mapmatch bench`` and ``benchmarks/``.
"""
