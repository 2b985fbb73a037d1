/*
 * Deliberate misuse of the C API: every status code from RKMPM_ERR_NULL_POINTER (1) to
 * RKMPM_ERR_UNSUPPORTED (12, an RK shape of order 2 with the APIC transfer) is provoked, and for
 * each failure the driver checks
 *  - the exact status,
 *  - that rkmpm_last_error_message() has a message, and that it names the failing function
 *    (so it is the message of this failure, not a stale one),
 *  - that the simulation is unchanged (particle count, time, step count and every particle
 *    field, compared bit for bit) where the call had a simulation to change.
 * It also checks the library-level functions (version, ABI, status strings), the truncation
 * contract of rkmpm_last_error_message, that the message is per thread, and that the body-force
 * callback receives what the header promises. RKMPM_ERR_PANIC (13) cannot be provoked on
 * purpose. Exits non-zero on any mismatch.
 */
#include "rkmpm.h"
#include "rkmpm_check.h"
#include "snapshot.h"

#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <threads.h>

static int failures = 0;
static int checks = 0;

#define EXPECT(cond, ...)                                                                          \
  do {                                                                                             \
    ++checks;                                                                                      \
    if (!(cond)) {                                                                                 \
      fprintf(stderr, "FAIL (line %d): ", __LINE__);                                               \
      fprintf(stderr, __VA_ARGS__);                                                                \
      fputc('\n', stderr);                                                                         \
      ++failures;                                                                                  \
    }                                                                                              \
  } while (0)

/* Checks the status of `call`; for a failure also that a message naming `function` exists. */
static void expect_status(RkmpmStatus got, RkmpmStatus want, const char *function,
                          const char *call, int line) {
  ++checks;
  char *message = rkmpm_example_last_error();
  if (got != want) {
    fprintf(stderr, "FAIL (line %d): %s returned %d (%s), expected %d (%s); last message: %s\n",
            line, call, (int)got, rkmpm_status_str((int32_t)got), (int)want,
            rkmpm_status_str((int32_t)want), message);
    ++failures;
  } else if (want != RKMPM_OK) {
    if (message[0] == '\0' || strstr(message, function) == NULL) {
      fprintf(stderr, "FAIL (line %d): %s gave status %d but the last message \"%s\" does not "
                      "name %s\n",
              line, call, (int)got, message, function);
      ++failures;
    } else {
      printf("ok %2d %-28s %s\n", (int)got, rkmpm_status_str((int32_t)got), message);
    }
  }
  free(message);
}

#define EXPECT_STATUS(call, want, function) expect_status((call), (want), (function), #call, __LINE__)

/* Everything a caller can observe of a simulation (snapshot.h): every particle field, the
   counts, the time and the step count. */
static Snapshot snapshot(const RkmpmSim *sim) { return snapshot_take(sim); }

static void release(Snapshot *s) { snapshot_release(s); }

static void expect_same(const Snapshot *a, const Snapshot *b, const char *call, int line) {
  ++checks;
  char what[256];
  if (!snapshot_compare(a, b, what, sizeof what)) {
    fprintf(stderr, "FAIL (line %d): %s changed the simulation (%s)\n", line, call, what);
    ++failures;
  }
}

/* A failing call that must leave `sim` exactly as it was. */
#define EXPECT_FAIL_UNCHANGED(sim, call, want, function)                                           \
  do {                                                                                             \
    Snapshot before_ = snapshot(sim);                                                              \
    expect_status((call), (want), (function), #call, __LINE__);                                    \
    Snapshot after_ = snapshot(sim);                                                               \
    expect_same(&before_, &after_, #call, __LINE__);                                               \
    release(&before_);                                                                             \
    release(&after_);                                                                              \
  } while (0)

/* A 2D block of particles: grid of 10 x 10 cells of 0.1 from the origin, particles 2 per cell
   per direction on [0.3, 0.7]^2 (64 particles), one linear elastic material. */
static const double H = 0.1;

static RkmpmSim *make_block(double density, double young, double poisson, double vx,
                            uint32_t *material) {
  const double origin[2] = {0.0, 0.0};
  const size_t cells[2] = {10, 10};
  RkmpmSim *sim = NULL;
  RKMPM_CHECK(rkmpm_sim_new(2, origin, cells, H, &sim));
  RKMPM_CHECK(rkmpm_sim_add_material_linear_elastic(sim, density, young, poisson, material));
  double x[64 * 2], v[64 * 2], vol[64];
  int p = 0;
  for (int j = 0; j < 8; ++j) {
    for (int i = 0; i < 8; ++i) {
      x[2 * p] = 0.3 + (i + 0.5) * H / 2.0;
      x[2 * p + 1] = 0.3 + (j + 0.5) * H / 2.0;
      v[2 * p] = vx * (1.0 + 0.1 * j);
      v[2 * p + 1] = -0.5 * vx;
      vol[p] = H * H / 4.0;
      ++p;
    }
  }
  RKMPM_CHECK(rkmpm_sim_add_particles(sim, *material, 64, x, vol, v));
  return sim;
}

/* ---- body-force callbacks ---- */

enum ForceMode {
  FORCE_RECORD,       /* checks its arguments, writes a small constant acceleration */
  FORCE_RETURN_ERROR, /* returns 1 */
  FORCE_WRITE_NAN,    /* writes NaN */
  FORCE_WRITE_INF,    /* writes +inf */
  FORCE_HUGE,         /* writes DBL_MAX: finite, but the grid forces overflow */
  FORCE_CONVERGE      /* a = -k (x - c) along x: the particles cross over, det F < 0 */
};

typedef struct {
  enum ForceMode mode;
  int calls;
  int arguments_ok;
  const Snapshot *expected; /* FORCE_RECORD: the state before the step (the callback must not
                               call back into the simulation that is stepping) */
  double k, center;       /* FORCE_CONVERGE */
} ForceData;

static int32_t body_force(void *user_data, double time, size_t count, uint32_t dim,
                          const double *reference_positions, const double *positions,
                          double *accelerations) {
  ForceData *data = user_data;
  ++data->calls;
  switch (data->mode) {
  case FORCE_RECORD: {
    const Snapshot *s = data->expected;
    data->arguments_ok =
        s != NULL && count == s->count && dim == 2 && time == s->time &&
        memcmp(reference_positions, s->fields[RKMPM_FIELD_REFERENCE_POSITION],
               count * dim * sizeof(double)) == 0 &&
        memcmp(positions, s->fields[RKMPM_FIELD_POSITION], count * dim * sizeof(double)) == 0;
    for (size_t i = 0; i < count * dim; ++i) {
      accelerations[i] = (i % dim == 1) ? -1.0 : 0.0;
    }
    return 0;
  }
  case FORCE_RETURN_ERROR:
    return 1;
  case FORCE_WRITE_NAN:
  case FORCE_WRITE_INF:
  case FORCE_HUGE:
    for (size_t i = 0; i < count * dim; ++i) {
      accelerations[i] = 0.0;
    }
    accelerations[dim * (count / 2)] = data->mode == FORCE_WRITE_NAN   ? NAN
                                       : data->mode == FORCE_WRITE_INF ? INFINITY
                                                                       : DBL_MAX;
    if (data->mode == FORCE_HUGE) {
      for (size_t p = 0; p < count; ++p) {
        accelerations[p * dim] = DBL_MAX;
      }
    }
    return 0;
  case FORCE_CONVERGE:
    for (size_t p = 0; p < count; ++p) {
      accelerations[p * dim] = -data->k * (positions[p * dim] - data->center);
      for (uint32_t d = 1; d < dim; ++d) {
        accelerations[p * dim + d] = 0.0;
      }
    }
    return 0;
  }
  return 2;
}

/* ---- per-thread message ---- */

typedef struct {
  size_t initial_length;
  RkmpmStatus status;
  size_t length_after;
} ThreadResult;

static int thread_main(void *arg) {
  ThreadResult *r = arg;
  r->initial_length = rkmpm_last_error_message(NULL, 0);
  r->status = rkmpm_sim_step(NULL, 1.0);
  r->length_after = rkmpm_last_error_message(NULL, 0);
  return 0;
}

int main(void) {
  /* Failures go to stderr: keep stdout line-buffered so the two interleave readably. */
  setvbuf(stdout, NULL, _IOLBF, 0);

  /* ---- library-level functions ---- */
  EXPECT(rkmpm_abi_version() == RKMPM_ABI_VERSION, "ABI version %u, header %u",
         (unsigned)rkmpm_abi_version(), (unsigned)RKMPM_ABI_VERSION);
  EXPECT(rkmpm_version() != NULL && rkmpm_version()[0] != '\0', "empty version string");
  printf("rkmpm %s, ABI %u\n", rkmpm_version(), (unsigned)rkmpm_abi_version());

  const char *names[15];
  for (int32_t s = 0; s <= 14; ++s) {
    names[s] = rkmpm_status_str(s);
    EXPECT(names[s] != NULL && names[s][0] != '\0', "status %d has no string", (int)s);
    if (names[s] == NULL) {
      names[s] = "";
    }
    EXPECT(strcmp(names[s], "unknown status") != 0, "status %d is described as unknown", (int)s);
    for (int32_t t = 0; t < s; ++t) {
      EXPECT(strcmp(names[s], names[t]) != 0, "statuses %d and %d share the string \"%s\"",
             (int)t, (int)s, names[s]);
    }
  }
  EXPECT(rkmpm_status_str(99) != NULL && strcmp(rkmpm_status_str(99), "unknown status") == 0,
         "status 99 should be \"unknown status\"");
  EXPECT(rkmpm_status_str(-1) != NULL && strcmp(rkmpm_status_str(-1), "unknown status") == 0,
         "status -1 should be \"unknown status\"");

  rkmpm_sim_free(NULL); /* a no-op */
  EXPECT(rkmpm_sim_particle_count(NULL) == 0, "particle count of NULL");

  /* ---- rkmpm_sim_new ---- */
  const double origin[3] = {0.0, 0.0, 0.0};
  const size_t cells[3] = {10, 10, 10};
  RkmpmSim *sim = NULL;
  RkmpmSim *const not_null = (RkmpmSim *)(uintptr_t)&failures;
  EXPECT_STATUS(rkmpm_sim_new(2, origin, cells, H, NULL), RKMPM_ERR_NULL_POINTER, "rkmpm_sim_new");
  sim = not_null;
  EXPECT_STATUS(rkmpm_sim_new(2, NULL, cells, H, &sim), RKMPM_ERR_NULL_POINTER, "rkmpm_sim_new");
  EXPECT(sim == NULL, "rkmpm_sim_new must write NULL to *out on failure");
  EXPECT_STATUS(rkmpm_sim_new(2, origin, NULL, H, &sim), RKMPM_ERR_NULL_POINTER, "rkmpm_sim_new");
  sim = not_null;
  EXPECT_STATUS(rkmpm_sim_new(4, origin, cells, H, &sim), RKMPM_ERR_INVALID_ARGUMENT,
                "rkmpm_sim_new");
  EXPECT(sim == NULL, "rkmpm_sim_new must write NULL to *out on failure");
  EXPECT_STATUS(rkmpm_sim_new(1, origin, cells, H, &sim), RKMPM_ERR_INVALID_ARGUMENT,
                "rkmpm_sim_new");
  EXPECT_STATUS(rkmpm_sim_new(0, origin, cells, H, &sim), RKMPM_ERR_INVALID_ARGUMENT,
                "rkmpm_sim_new");
  EXPECT_STATUS(rkmpm_sim_new(2, origin, cells, -0.1, &sim), RKMPM_ERR_INVALID_ARGUMENT,
                "rkmpm_sim_new");
  EXPECT_STATUS(rkmpm_sim_new(2, origin, cells, 0.0, &sim), RKMPM_ERR_INVALID_ARGUMENT,
                "rkmpm_sim_new");
  EXPECT_STATUS(rkmpm_sim_new(3, origin, cells, NAN, &sim), RKMPM_ERR_INVALID_ARGUMENT,
                "rkmpm_sim_new");
  const size_t zero_cells[2] = {10, 0};
  EXPECT_STATUS(rkmpm_sim_new(2, origin, zero_cells, H, &sim), RKMPM_ERR_INVALID_ARGUMENT,
                "rkmpm_sim_new");
  const double nan_origin[2] = {0.0, NAN};
  EXPECT_STATUS(rkmpm_sim_new(2, nan_origin, cells, H, &sim), RKMPM_ERR_INVALID_ARGUMENT,
                "rkmpm_sim_new");
  EXPECT(sim == NULL, "rkmpm_sim_new must write NULL to *out on failure");

  /* ---- the truncation contract of rkmpm_last_error_message ---- */
  {
    EXPECT_STATUS(rkmpm_sim_new(4, origin, cells, H, &sim), RKMPM_ERR_INVALID_ARGUMENT,
                  "rkmpm_sim_new");
    const size_t full = rkmpm_last_error_message(NULL, 0);
    EXPECT(full > 8, "message length %zu", full);
    char *whole = rkmpm_example_last_error();
    EXPECT(strlen(whole) == full, "full message has %zu bytes, reported %zu", strlen(whole), full);
    char tiny[8];
    memset(tiny, 'X', sizeof tiny);
    EXPECT(rkmpm_last_error_message(tiny, sizeof tiny) == full,
           "a short buffer must still return the full length");
    EXPECT(tiny[7] == '\0' && strlen(tiny) == 7 && memcmp(tiny, whole, 7) == 0,
           "short buffer must hold the first 7 bytes and a NUL");
    char one = 'X';
    EXPECT(rkmpm_last_error_message(&one, 1) == full && one == '\0',
           "a one-byte buffer gets just the NUL");
    char exact[512];
    if (full + 1 <= sizeof exact) {
      memset(exact, 'X', sizeof exact);
      EXPECT(rkmpm_last_error_message(exact, full + 1) == full && strcmp(exact, whole) == 0,
             "a buffer of full + 1 bytes gets the whole message");
      EXPECT(exact[full + 1] == 'X', "wrote past len");
    }

    /* The message is per thread: a new thread starts with none, and its failure does not
       replace this thread's message. */
    ThreadResult r = {99, RKMPM_OK, 0};
    thrd_t thread;
    EXPECT(thrd_create(&thread, thread_main, &r) == thrd_success, "thrd_create");
    thrd_join(thread, NULL);
    EXPECT(r.initial_length == 0, "a new thread sees a message of length %zu", r.initial_length);
    EXPECT(r.status == RKMPM_ERR_NULL_POINTER && r.length_after > 0,
           "rkmpm_sim_step(NULL) on another thread gave %d with a message of %zu bytes",
           (int)r.status, r.length_after);
    char *again = rkmpm_example_last_error();
    EXPECT(strcmp(again, whole) == 0, "another thread's failure changed this thread's message");
    free(again);
    free(whole);
  }

  /* ---- NULL handles and NULL out pointers (1) ---- */
  uint32_t dim = 0;
  double t = 0.0;
  uint64_t steps = 0;
  EXPECT_STATUS(rkmpm_sim_dim(NULL, &dim), RKMPM_ERR_NULL_POINTER, "rkmpm_sim_dim");
  EXPECT_STATUS(rkmpm_sim_time(NULL, &t), RKMPM_ERR_NULL_POINTER, "rkmpm_sim_time");
  EXPECT_STATUS(rkmpm_sim_step(NULL, 1e-3), RKMPM_ERR_NULL_POINTER, "rkmpm_sim_step");
  EXPECT_STATUS(rkmpm_sim_set_shape(NULL, RKMPM_SHAPE_LINEAR, 0, 0.0), RKMPM_ERR_NULL_POINTER,
                "rkmpm_sim_set_shape");
  EXPECT_STATUS(rkmpm_sim_write_vtk(NULL, "x.vtu"), RKMPM_ERR_NULL_POINTER, "rkmpm_sim_write_vtk");

  uint32_t material = 99;
  sim = make_block(1.0, 100.0, 0.3, 0.05, &material);
  EXPECT(material == 0, "first material id %u", (unsigned)material);
  const size_t count = rkmpm_sim_particle_count(sim);
  EXPECT(count == 64, "particle count %zu", count);
  RKMPM_CHECK(rkmpm_sim_dim(sim, &dim));
  EXPECT(dim == 2, "dim %u", (unsigned)dim);

  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_dim(sim, NULL), RKMPM_ERR_NULL_POINTER, "rkmpm_sim_dim");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_time(sim, NULL), RKMPM_ERR_NULL_POINTER, "rkmpm_sim_time");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_step_count(sim, NULL), RKMPM_ERR_NULL_POINTER,
                        "rkmpm_sim_step_count");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_stable_dt(sim, 0.5, NULL), RKMPM_ERR_NULL_POINTER,
                        "rkmpm_sim_stable_dt");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_field_len(sim, RKMPM_FIELD_MASS, NULL),
                        RKMPM_ERR_NULL_POINTER, "rkmpm_sim_field_len");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_gravity(sim, NULL), RKMPM_ERR_NULL_POINTER,
                        "rkmpm_sim_set_gravity");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_material_linear_elastic(sim, 1.0, 1.0, 0.0, NULL),
                        RKMPM_ERR_NULL_POINTER, "rkmpm_sim_add_material_linear_elastic");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_material_neo_hookean(sim, 1.0, 1.0, 0.0, NULL),
                        RKMPM_ERR_NULL_POINTER, "rkmpm_sim_add_material_neo_hookean");
  EXPECT_FAIL_UNCHANGED(sim,
                        rkmpm_sim_add_material_drucker_prager(sim, 1.0, 1.0, 0.0, 30.0, 0.0, 0.0,
                                                              NULL),
                        RKMPM_ERR_NULL_POINTER, "rkmpm_sim_add_material_drucker_prager");
  {
    uint32_t unused = 0;
    EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_material_johnson_cook(sim, NULL, &unused),
                          RKMPM_ERR_NULL_POINTER, "rkmpm_sim_add_material_johnson_cook");
  }
  const double one_x[2] = {0.5, 0.5}, one_vol[1] = {1e-3};
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_particles(sim, material, 1, NULL, one_vol, NULL),
                        RKMPM_ERR_NULL_POINTER, "rkmpm_sim_add_particles");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_particles(sim, material, 1, one_x, NULL, NULL),
                        RKMPM_ERR_NULL_POINTER, "rkmpm_sim_add_particles");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_get_particles(sim, RKMPM_FIELD_POSITION, NULL, 1000),
                        RKMPM_ERR_NULL_POINTER, "rkmpm_sim_get_particles");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_write_vtk(sim, NULL), RKMPM_ERR_NULL_POINTER,
                        "rkmpm_sim_write_vtk");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_write_vtk_frame(sim, NULL), RKMPM_ERR_NULL_POINTER,
                        "rkmpm_sim_write_vtk_frame");

  /* ---- invalid arguments (2) ---- */
  const double nan_g[2] = {0.0, NAN}, inf_g[2] = {INFINITY, 0.0};
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_gravity(sim, nan_g), RKMPM_ERR_INVALID_ARGUMENT,
                        "rkmpm_sim_set_gravity");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_gravity(sim, inf_g), RKMPM_ERR_INVALID_ARGUMENT,
                        "rkmpm_sim_set_gravity");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_shape(sim, 77, 0, 0.0), RKMPM_ERR_INVALID_ARGUMENT,
                        "rkmpm_sim_set_shape");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_integration(sim, 9, 0), RKMPM_ERR_INVALID_ARGUMENT,
                        "rkmpm_sim_set_integration");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_transfer(sim, 5, 0.0), RKMPM_ERR_INVALID_ARGUMENT,
                        "rkmpm_sim_set_transfer");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_transfer(sim, RKMPM_TRANSFER_PIC_FLIP, 1.5),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_transfer");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_transfer(sim, RKMPM_TRANSFER_PIC_FLIP, -0.1),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_transfer");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_transfer(sim, RKMPM_TRANSFER_PIC_FLIP, NAN),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_transfer");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_scheme(sim, 7), RKMPM_ERR_INVALID_ARGUMENT,
                        "rkmpm_sim_set_scheme");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_boundary(sim, 0, -1, 9, 0.0),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_boundary");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_boundary(sim, 0, 0, RKMPM_BOUNDARY_FIXED, 0.0),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_boundary");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_boundary(sim, 0, 2, RKMPM_BOUNDARY_FIXED, 0.0),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_boundary");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_boundary(sim, 5, 1, RKMPM_BOUNDARY_FIXED, 0.0),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_boundary");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_boundary(sim, 2, 1, RKMPM_BOUNDARY_FIXED, 0.0),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_boundary");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_boundary(sim, 1, -1, RKMPM_BOUNDARY_FRICTION, -0.5),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_boundary");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_boundary(sim, 1, -1, RKMPM_BOUNDARY_FRICTION, NAN),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_boundary");
  uint32_t id = 77;
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_material_linear_elastic(sim, -1.0, 100.0, 0.3, &id),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_material_linear_elastic");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_material_linear_elastic(sim, 1.0, 0.0, 0.3, &id),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_material_linear_elastic");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_material_linear_elastic(sim, 1.0, 100.0, 0.5, &id),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_material_linear_elastic");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_material_linear_elastic(sim, 1.0, 100.0, -1.0, &id),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_material_linear_elastic");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_material_neo_hookean(sim, NAN, 100.0, 0.3, &id),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_material_neo_hookean");
  EXPECT_FAIL_UNCHANGED(sim,
                        rkmpm_sim_add_material_drucker_prager(sim, 2650.0, 1e6, 0.3, 30.0, 0.0,
                                                              31.0, &id),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_material_drucker_prager");
  {
    /* OFHC copper, with a flag that is neither 0 nor 1, then a melt below room temperature. */
    RkmpmJohnsonCook jc = {8960.0, 124e9, 0.34, 90e6, 292e6, 0.31, 0.025, 1.0, 1.09, 298.0,
                           1356.0, 383.0, 0.9, 2, 0.54, 4.89, -3.03, 0.014, 1.12, 0, 0.0, 0.0, 0.0};
    EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_material_johnson_cook(sim, &jc, &id),
                          RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_material_johnson_cook");
    jc.damage_enabled = 1;
    jc.melt_temperature = 200.0;
    EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_material_johnson_cook(sim, &jc, &id),
                          RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_material_johnson_cook");
  }
  /* Failed additions do not use up ids: the next material gets id 1. */
  RKMPM_CHECK(rkmpm_sim_add_material_neo_hookean(sim, 1.0, 100.0, 0.3, &id));
  EXPECT(id == 1, "second material got id %u", (unsigned)id);

  const double bad_x[4] = {0.5, 0.5, 0.5, NAN}, two_vol[2] = {1e-3, 1e-3};
  const double zero_vol[2] = {1e-3, 0.0}, two_x[4] = {0.5, 0.5, 0.6, 0.6};
  const double inf_v[4] = {0.0, 0.0, INFINITY, 0.0};
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_particles(sim, material, 2, bad_x, two_vol, NULL),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_particles");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_particles(sim, material, 2, two_x, zero_vol, NULL),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_particles");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_particles(sim, material, 2, two_x, two_vol, inf_v),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_particles");
  double dt = 0.0;
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_stable_dt(sim, 0.0, &dt), RKMPM_ERR_INVALID_ARGUMENT,
                        "rkmpm_sim_stable_dt");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_stable_dt(sim, 1.5, &dt), RKMPM_ERR_INVALID_ARGUMENT,
                        "rkmpm_sim_stable_dt");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_stable_dt(sim, NAN, &dt), RKMPM_ERR_INVALID_ARGUMENT,
                        "rkmpm_sim_stable_dt");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_step(sim, 0.0), RKMPM_ERR_INVALID_ARGUMENT,
                        "rkmpm_sim_step");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_step(sim, -1e-4), RKMPM_ERR_INVALID_ARGUMENT,
                        "rkmpm_sim_step");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_step(sim, NAN), RKMPM_ERR_INVALID_ARGUMENT,
                        "rkmpm_sim_step");
  size_t len = 0;
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_field_len(sim, 77, &len), RKMPM_ERR_INVALID_ARGUMENT,
                        "rkmpm_sim_field_len");
  double big[64 * 4 + 1];
  for (size_t i = 0; i < 64 * 4 + 1; ++i) {
    big[i] = -12345.0;
  }
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_get_particles(sim, 77, big, 64 * 4 + 1),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_get_particles");
  EXPECT(big[0] == -12345.0, "get_particles with an unknown field wrote into the buffer");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_write_vtk(sim, "\xff\xfe.vtu"), RKMPM_ERR_INVALID_ARGUMENT,
                        "rkmpm_sim_write_vtk");

  /* ---- buffer too small (3): nothing written ---- */
  for (RkmpmField f = RKMPM_FIELD_POSITION; f <= RKMPM_FIELD_DEFORMATION_GRADIENT; ++f) {
    RKMPM_CHECK(rkmpm_sim_field_len(sim, f, &len));
    const size_t per = (f == RKMPM_FIELD_STRESS || f == RKMPM_FIELD_DEFORMATION_GRADIENT) ? 4
                       : (f == RKMPM_FIELD_PRESSURE || f == RKMPM_FIELD_VOLUME ||
                          f == RKMPM_FIELD_MASS)
                           ? 1
                           : 2;
    EXPECT(len == per * count, "field %u: length %zu, expected %zu", (unsigned)f, len,
           per * count);
    for (size_t i = 0; i < 64 * 4 + 1; ++i) {
      big[i] = -12345.0;
    }
    EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_get_particles(sim, f, big, len - 1),
                          RKMPM_ERR_BUFFER_TOO_SMALL, "rkmpm_sim_get_particles");
    int untouched = 1;
    for (size_t i = 0; i < 64 * 4 + 1; ++i) {
      untouched = untouched && big[i] == -12345.0;
    }
    EXPECT(untouched, "field %u: a too-small buffer was written to", (unsigned)f);
    /* The exact length works and writes exactly len values. */
    RKMPM_CHECK(rkmpm_sim_get_particles(sim, f, big, len));
    EXPECT(big[len] == -12345.0, "field %u: wrote past the needed length", (unsigned)f);
  }
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_get_particles(sim, RKMPM_FIELD_MASS, NULL, 0),
                        RKMPM_ERR_BUFFER_TOO_SMALL, "rkmpm_sim_get_particles");

  /* ---- unknown material (5), outside the grid (6) on insertion ---- */
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_particles(sim, 99, 2, two_x, two_vol, NULL),
                        RKMPM_ERR_UNKNOWN_MATERIAL, "rkmpm_sim_add_particles");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_particles(sim, 2, 2, two_x, two_vol, NULL),
                        RKMPM_ERR_UNKNOWN_MATERIAL, "rkmpm_sim_add_particles");
  const double outside_x[4] = {0.5, 0.5, 1.5, 0.5}; /* the second one is outside [0, 1]^2 */
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_particles(sim, material, 2, outside_x, two_vol, NULL),
                        RKMPM_ERR_OUTSIDE_GRID, "rkmpm_sim_add_particles");
  const double below_x[2] = {0.5, -1e-9};
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_particles(sim, material, 1, below_x, one_vol, NULL),
                        RKMPM_ERR_OUTSIDE_GRID, "rkmpm_sim_add_particles");

  /* ---- boundary points: NULL (1), invalid (2), outside the grid (6) ---- */
  {
    const double bx[4] = {0.3, 0.4, 0.3, 0.6}, bn[4] = {-0.05, 0.0, -0.05, 0.0};
    const double bt[4] = {0.0, 0.0, 0.0, 0.0};
    size_t nb = 99;
    RKMPM_CHECK(rkmpm_sim_boundary_point_count(sim, &nb));
    EXPECT(nb == 0, "a new simulation has %zu boundary points", nb);
    EXPECT_STATUS(rkmpm_sim_boundary_point_count(NULL, &nb), RKMPM_ERR_NULL_POINTER,
                  "rkmpm_sim_boundary_point_count");
    EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_boundary_point_count(sim, NULL), RKMPM_ERR_NULL_POINTER,
                          "rkmpm_sim_boundary_point_count");
    EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_boundary_points(sim, 2, NULL, bn, NULL),
                          RKMPM_ERR_NULL_POINTER, "rkmpm_sim_add_boundary_points");
    EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_boundary_points(sim, 2, bx, NULL, bt),
                          RKMPM_ERR_NULL_POINTER, "rkmpm_sim_add_boundary_points");
    const double zero_n[4] = {-0.05, 0.0, 0.0, 0.0}, nan_n[4] = {-0.05, 0.0, NAN, 0.0};
    const double inf_t[4] = {0.0, 0.0, 0.0, INFINITY};
    const double nan_x[4] = {0.3, 0.4, 0.3, NAN}, out_x[4] = {0.3, 0.4, 0.3, 1.6};
    EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_boundary_points(sim, 2, bx, zero_n, NULL),
                          RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_boundary_points");
    EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_boundary_points(sim, 2, bx, nan_n, NULL),
                          RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_boundary_points");
    EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_boundary_points(sim, 2, bx, bn, inf_t),
                          RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_boundary_points");
    /* A NaN position is "not finite" (2), as for particles, not "outside the grid". */
    EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_boundary_points(sim, 2, nan_x, bn, NULL),
                          RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_add_boundary_points");
    EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_add_boundary_points(sim, 2, out_x, bn, NULL),
                          RKMPM_ERR_OUTSIDE_GRID, "rkmpm_sim_add_boundary_points");
    RKMPM_CHECK(rkmpm_sim_add_boundary_points(sim, 2, bx, bn, NULL));
    RKMPM_CHECK(rkmpm_sim_add_boundary_points(sim, 1, bx, bn, bt));
    RKMPM_CHECK(rkmpm_sim_boundary_point_count(sim, &nb));
    EXPECT(nb == 3, "%zu boundary points after adding 2 + 1", nb);
  }

  double critical = 0.0;
  RKMPM_CHECK(rkmpm_sim_stable_dt(sim, 1.0, &critical));
  RKMPM_CHECK(rkmpm_sim_stable_dt(sim, 0.5, &dt));
  EXPECT(dt == 0.5 * critical, "stable_dt(0.5) = %.17g, stable_dt(1) = %.17g", dt, critical);

  /* ---- RK and VC parameters (2); RK of order >= 2 with APIC (12, refused by the step) ---- */
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_shape(sim, RKMPM_SHAPE_RK, 0, 2.0),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_shape");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_shape(sim, RKMPM_SHAPE_RK, 6, 4.0),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_shape");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_shape(sim, RKMPM_SHAPE_RK, 2, 1.0),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_shape");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_shape(sim, RKMPM_SHAPE_RK, 1, NAN),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_shape");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_integration(sim, RKMPM_INTEGRATION_VC, 0),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_integration");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_integration(sim, RKMPM_INTEGRATION_VC, 5),
                        RKMPM_ERR_INVALID_ARGUMENT, "rkmpm_sim_set_integration");
  RKMPM_CHECK(rkmpm_sim_set_shape(sim, RKMPM_SHAPE_RK, 2, 3.0)); /* transfer is still APIC */
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_step(sim, dt), RKMPM_ERR_UNSUPPORTED, "rkmpm_sim_step");
  /* A failed step is not a first step: the options can still change. */
  RKMPM_CHECK(rkmpm_sim_set_shape(sim, RKMPM_SHAPE_BSPLINE2, 0, 0.0));

  /* ---- the time step (7) ---- */
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_step(sim, 10.0 * critical), RKMPM_ERR_UNSTABLE_TIME_STEP,
                        "rkmpm_sim_step");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_step(sim, 1.01 * critical), RKMPM_ERR_UNSTABLE_TIME_STEP,
                        "rkmpm_sim_step");

  /* ---- the body-force callback: arguments, then failures (10) ---- */
  ForceData force = {FORCE_RECORD, 0, 0, NULL, 0.0, 0.0};
  RKMPM_CHECK(rkmpm_sim_set_body_force(sim, body_force, &force));
  for (int s = 1; s <= 2; ++s) {
    Snapshot before = snapshot(sim);
    force.expected = &before;
    force.arguments_ok = 0;
    RKMPM_CHECK(rkmpm_sim_step(sim, dt));
    force.expected = NULL;
    release(&before);
    EXPECT(force.calls == s, "callback called %d times in %d steps", force.calls, s);
    EXPECT(force.arguments_ok, "step %d: callback arguments (count, dim, time, positions) wrong",
           s);
  }
  RKMPM_CHECK(rkmpm_sim_time(sim, &t));
  RKMPM_CHECK(rkmpm_sim_step_count(sim, &steps));
  EXPECT(t == dt + dt && steps == 2, "time %.17g (expected %.17g), steps %llu", t, dt + dt,
         (unsigned long long)steps);

  force.mode = FORCE_RETURN_ERROR;
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_step(sim, dt), RKMPM_ERR_CALLBACK, "rkmpm_sim_step");
  force.mode = FORCE_WRITE_NAN;
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_step(sim, dt), RKMPM_ERR_CALLBACK, "rkmpm_sim_step");
  force.mode = FORCE_WRITE_INF;
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_step(sim, dt), RKMPM_ERR_CALLBACK, "rkmpm_sim_step");

  /* ---- an inverted particle (9): a converging body force that folds the block over in x
     within one step: grid velocities -dt k (x - c), so F_xx = 1 - dt^2 k = -2 while the
     particles stay inside the grid (they land at c - 2 (x - c), within 0.4 of c = 0.5). ---- */
  force.mode = FORCE_CONVERGE;
  force.k = 3.0 / (dt * dt);
  force.center = 0.5;
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_step(sim, dt), RKMPM_ERR_INVERTED_PARTICLE,
                        "rkmpm_sim_step");

  /* Removing the callback: the next step does not call it. */
  RKMPM_CHECK(rkmpm_sim_set_body_force(sim, NULL, NULL));
  const int calls = force.calls;
  RKMPM_CHECK(rkmpm_sim_step(sim, dt));
  EXPECT(force.calls == calls, "a removed callback was called");

  /* ---- invalid state (4): options fixed by the first step; walls and gravity are not ---- */
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_shape(sim, RKMPM_SHAPE_BSPLINE3, 0, 0.0),
                        RKMPM_ERR_INVALID_STATE, "rkmpm_sim_set_shape");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_integration(sim, RKMPM_INTEGRATION_MP, 0),
                        RKMPM_ERR_INVALID_STATE, "rkmpm_sim_set_integration");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_transfer(sim, RKMPM_TRANSFER_PIC_FLIP, 0.0),
                        RKMPM_ERR_INVALID_STATE, "rkmpm_sim_set_transfer");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_set_scheme(sim, RKMPM_SCHEME_MUSL),
                        RKMPM_ERR_INVALID_STATE, "rkmpm_sim_set_scheme");
  const double g[2] = {0.0, -9.81};
  RKMPM_CHECK(rkmpm_sim_set_gravity(sim, g));
  RKMPM_CHECK(rkmpm_sim_set_boundary(sim, 1, -1, RKMPM_BOUNDARY_FRICTION, 0.3));
  RKMPM_CHECK(rkmpm_sim_step(sim, dt));
  {
    uint32_t empty_material = 0;
    RkmpmSim *empty = NULL;
    RKMPM_CHECK(rkmpm_sim_new(3, origin, cells, H, &empty));
    RKMPM_CHECK(rkmpm_sim_add_material_linear_elastic(empty, 1.0, 100.0, 0.3, &empty_material));
    EXPECT_FAIL_UNCHANGED(empty, rkmpm_sim_stable_dt(empty, 0.5, &dt), RKMPM_ERR_INVALID_STATE,
                          "rkmpm_sim_stable_dt");
    rkmpm_sim_free(empty);
  }

  /* ---- input/output (11) ---- */
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_write_vtk(sim, "rkmpm-no-such-directory/particles.vtu"),
                        RKMPM_ERR_IO, "rkmpm_sim_write_vtk");
  EXPECT_FAIL_UNCHANGED(sim, rkmpm_sim_write_vtk_frame(sim, "rkmpm-no-such-directory/frames"),
                        RKMPM_ERR_IO, "rkmpm_sim_write_vtk_frame");
  remove("error_handling_c.vtu");
  RKMPM_CHECK(rkmpm_sim_write_vtk(sim, "error_handling_c.vtu"));
  FILE *f = fopen("error_handling_c.vtu", "r");
  EXPECT(f != NULL, "rkmpm_sim_write_vtk reported success but wrote no file");
  if (f != NULL) {
    fclose(f);
  }
  remove("error_handling_c_series.pvd");
  RKMPM_CHECK(rkmpm_sim_write_vtk_frame(sim, "error_handling_c_series"));
  RKMPM_CHECK(rkmpm_sim_step(sim, dt));
  RKMPM_CHECK(rkmpm_sim_write_vtk_frame(sim, "error_handling_c_series"));
  f = fopen("error_handling_c_series.pvd", "r");
  EXPECT(f != NULL, "rkmpm_sim_write_vtk_frame wrote no .pvd file");
  if (f != NULL) {
    char text[8192];
    size_t n = fread(text, 1, sizeof text - 1, f);
    text[n] = '\0';
    fclose(f);
    int datasets = 0;
    for (const char *s = strstr(text, "<DataSet"); s != NULL; s = strstr(s + 1, "<DataSet")) {
      ++datasets;
    }
    EXPECT(datasets == 2, "the .pvd lists %d frames after two writes", datasets);
  }

  /* ---- leaving the grid during a step (6) ---- */
  {
    uint32_t m = 0;
    RkmpmSim *fast = NULL;
    RKMPM_CHECK(rkmpm_sim_new(2, origin, cells, H, &fast));
    RKMPM_CHECK(rkmpm_sim_add_material_linear_elastic(fast, 1.0, 100.0, 0.3, &m));
    const double x[2] = {0.99, 0.5}, v[2] = {1000.0, 0.0}, vol[1] = {H * H / 4.0};
    RKMPM_CHECK(rkmpm_sim_add_particles(fast, m, 1, x, vol, v));
    double dt_fast = 0.0;
    RKMPM_CHECK(rkmpm_sim_stable_dt(fast, 1.0, &dt_fast)); /* moves ~0.099 > 0.01 to the wall */
    EXPECT_FAIL_UNCHANGED(fast, rkmpm_sim_step(fast, dt_fast), RKMPM_ERR_OUTSIDE_GRID,
                          "rkmpm_sim_step");
    rkmpm_sim_free(fast);
  }

  /* ---- a non-finite step (8): heavy particles and a finite but huge body force (DBL_MAX):
     the grid force sum m_p N_Ip b_p overflows to infinity. ---- */
  {
    uint32_t m = 0;
    RkmpmSim *heavy = make_block(1.0e4, 1.0e6, 0.3, 0.0, &m);
    ForceData huge = {FORCE_HUGE, 0, 0, NULL, 0.0, 0.0};
    RKMPM_CHECK(rkmpm_sim_set_body_force(heavy, body_force, &huge));
    double dt_heavy = 0.0;
    RKMPM_CHECK(rkmpm_sim_stable_dt(heavy, 0.5, &dt_heavy));
    EXPECT_FAIL_UNCHANGED(heavy, rkmpm_sim_step(heavy, dt_heavy), RKMPM_ERR_NON_FINITE,
                          "rkmpm_sim_step");
    EXPECT(huge.calls == 1, "callback calls %d", huge.calls);
    rkmpm_sim_free(heavy);
  }

  rkmpm_sim_free(sim);
  printf("%d checks, %d failures\n", checks, failures);
  return failures == 0 ? EXIT_SUCCESS : EXIT_FAILURE;
}
