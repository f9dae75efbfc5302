"""A third blind generator for ``soakcal diagnose`` (issue 22), written apart from the twin
(``simulators/truth.py``), the first blind generator and ``gen2``: the sensor is a full 3×3
gain matrix K(T) quadratic in temperature plus a cubic bias, not the seed's SFEM chain; the
noise is built from raw samples (white, heavy-tailed per capture, slow vibration,
quantisation, re-seating of a hand fixture, a quantised temperature channel on a lagging
die). By default every case is a null: nothing outside the base model's class is drawn;
``run --effect NAME --size S`` draws one catalogue effect into the same cases at S × a
detectable size gen3 defines from its own drawn noise (``effects``), scored by ``score``.

Modules: ``sensor`` (the gain-and-bias sensor), ``schedules`` (orientations),
``thermal`` (air, die, channels), ``noise`` (one capture from its raw samples),
``protocol`` (plateaus, visits, timing), ``case`` (one seeded case → CSV rows),
``writer`` (the recording CSV), ``stats`` (Clopper–Pearson), ``run`` (the benchmark),
``effects`` (catalogue effects and their size rule), ``score`` (right / not established /
wrong / missed); ``separable`` (a scorer that imports the diagnosis, as no generator
module does: gen2's oracle of separability on gen3's cases).
"""
