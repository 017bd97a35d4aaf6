"""The reference solutions of mexone's shipped course (`solutions/<exercise>/<file>`), which
mexone finds through the entry-point group `mexone.solutions` (Exercise.solution). Keep this
pack off the students' machines and out of their submissions' reach: it holds every answer."""
