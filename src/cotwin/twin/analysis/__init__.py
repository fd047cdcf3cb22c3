"""Many runs, or runs judged: sweeps, generated tests run on a twin, walks, fleets of live twins on Ray.
May import every other part of the twin."""
