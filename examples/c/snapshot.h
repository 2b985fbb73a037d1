/*
 * Everything a caller can observe of a simulation, taken at one moment, to check that a failing
 * call left the simulation unchanged: dimension, particle count, boundary-point count, time, step
 * count and every particle field (all RKMPM_FIELD_* values), compared bit for bit.
 * Shared by the C example drivers (error_handling.c, api_checks.c).
 */
#ifndef RKMPM_EXAMPLES_SNAPSHOT_H
#define RKMPM_EXAMPLES_SNAPSHOT_H

#include "rkmpm.h"
#include "rkmpm_check.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* RKMPM_FIELD_POSITION .. RKMPM_FIELD_DAMAGE */
#define SNAPSHOT_FIELDS 11

typedef struct {
  uint32_t dim;
  size_t count;
  size_t boundary_points;
  double time;
  uint64_t steps;
  size_t len[SNAPSHOT_FIELDS];
  double *fields[SNAPSHOT_FIELDS];
} Snapshot;

/* Takes a snapshot of a live simulation (every query must succeed; exits otherwise). */
static inline Snapshot snapshot_take(const RkmpmSim *sim) {
  Snapshot s;
  memset(&s, 0, sizeof s);
  RKMPM_CHECK(rkmpm_sim_dim(sim, &s.dim));
  s.count = rkmpm_sim_particle_count(sim);
  RKMPM_CHECK(rkmpm_sim_time(sim, &s.time));
  RKMPM_CHECK(rkmpm_sim_step_count(sim, &s.steps));
  RKMPM_CHECK(rkmpm_sim_boundary_point_count(sim, &s.boundary_points));
  for (RkmpmField f = 0; f < SNAPSHOT_FIELDS; ++f) {
    RKMPM_CHECK(rkmpm_sim_field_len(sim, f, &s.len[f]));
    s.fields[f] = malloc((s.len[f] + 1) * sizeof(double));
    if (s.fields[f] == NULL) {
      fprintf(stderr, "out of memory\n");
      exit(EXIT_FAILURE);
    }
    RKMPM_CHECK(rkmpm_sim_get_particles(sim, f, s.fields[f], s.len[f]));
  }
  return s;
}

static inline void snapshot_release(Snapshot *s) {
  for (int f = 0; f < SNAPSHOT_FIELDS; ++f) {
    free(s->fields[f]);
    s->fields[f] = NULL;
  }
}

/* Writes a description of the first difference into `what` (empty when there is none) and
   returns 1 when the snapshots are equal bit for bit. */
static inline int snapshot_compare(const Snapshot *a, const Snapshot *b, char *what, size_t len) {
  if (len > 0) {
    what[0] = '\0';
  }
  if (a->dim != b->dim) {
    snprintf(what, len, "dimension %u -> %u", (unsigned)a->dim, (unsigned)b->dim);
    return 0;
  }
  if (a->count != b->count) {
    snprintf(what, len, "particle count %zu -> %zu", a->count, b->count);
    return 0;
  }
  if (a->boundary_points != b->boundary_points) {
    snprintf(what, len, "boundary points %zu -> %zu", a->boundary_points, b->boundary_points);
    return 0;
  }
  if (memcmp(&a->time, &b->time, sizeof a->time) != 0) {
    snprintf(what, len, "time %.17g -> %.17g", a->time, b->time);
    return 0;
  }
  if (a->steps != b->steps) {
    snprintf(what, len, "steps %llu -> %llu", (unsigned long long)a->steps,
             (unsigned long long)b->steps);
    return 0;
  }
  for (int f = 0; f < SNAPSHOT_FIELDS; ++f) {
    if (a->len[f] != b->len[f]) {
      snprintf(what, len, "field %d length %zu -> %zu", f, a->len[f], b->len[f]);
      return 0;
    }
    for (size_t i = 0; i < a->len[f]; ++i) {
      if (memcmp(&a->fields[f][i], &b->fields[f][i], sizeof(double)) != 0) {
        snprintf(what, len, "field %d value %zu: %.17g -> %.17g", f, i, a->fields[f][i],
                 b->fields[f][i]);
        return 0;
      }
    }
  }
  return 1;
}

#endif /* RKMPM_EXAMPLES_SNAPSHOT_H */
