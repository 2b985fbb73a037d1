/*
 * Every row of docs/C_API_CHECKS.md, driven from C: each `ROW(id, status)` block provokes one
 * row of the table and checks
 *  - the exact status (`status` is the one the table gives; NO_STATUS for functions that return
 *    no status),
 *  - for a failure, that rkmpm_last_error_message() starts with the name of the row's function,
 *    ": " and a non-empty text (a message of another function is set just before each call, so a
 *    stale message cannot pass),
 *  - that the simulation is unchanged: dimension, particle count, boundary-point count, time,
 *    step count and every particle field, bit for bit (snapshot.h); that `*out` is NULL after a
 *    failed rkmpm_sim_new/rkmpm_sim_load; that output arguments and buffers are not written;
 *    that a rejected material uses up no id.
 * It prints `ok <id>` or `FAIL <id>` per row and exits non-zero on any mismatch.
 * tests/api_checks_table.rs checks that the rows here and in the table are the same, with the
 * same statuses.
 *
 * Usage: api_checks_c [scratch directory]   (files are written there; default ".")
 * With RKMPM_API_CHECKS_VERBOSE set, the message of every expected failure is printed too.
 */
#define _POSIX_C_SOURCE 200809L

#include "rkmpm.h"
#include "rkmpm_check.h"
#include "snapshot.h"

#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <threads.h>

/* ---- rows -------------------------------------------------------------------------------- */

/* The "status" of a row whose function returns no status. */
#define NO_STATUS (-1)

static const char *row_id = "";
static int row_want = NO_STATUS;
static char row_function[96];
static int row_problems = 0;
static int rows_ok = 0;
static int rows_failed = 0;
static const char *rows_seen[1024];
static int rows_seen_count = 0;
/* RKMPM_API_CHECKS_VERBOSE=1 prints the message of every expected failure. */
static int verbose = 0;

/* Functions named rkmpm_<prefix>; every other row prefix names rkmpm_sim_<prefix>. */
static const char *const library_functions[] = {"version", "abi_version", "status_str",
                                                "last_error_message"};

static void problem(int line, const char *format, ...) {
  va_list args;
  va_start(args, format);
  fprintf(stderr, "FAIL %s (line %d): ", row_id, line);
  vfprintf(stderr, format, args);
  fputc('\n', stderr);
  va_end(args);
  ++row_problems;
}

#define EXPECT(cond, ...)                                                                          \
  do {                                                                                             \
    if (!(cond)) {                                                                                 \
      problem(__LINE__, __VA_ARGS__);                                                              \
    }                                                                                              \
  } while (0)

static int row_begin(const char *id, int want) {
  row_id = id;
  row_want = want;
  row_problems = 0;
  for (int i = 0; i < rows_seen_count; ++i) {
    if (strcmp(rows_seen[i], id) == 0) {
      problem(__LINE__, "row id used twice");
    }
  }
  if (rows_seen_count < (int)(sizeof rows_seen / sizeof rows_seen[0])) {
    rows_seen[rows_seen_count++] = id;
  }
  const char *dot = strchr(id, '.');
  const int n = dot != NULL ? (int)(dot - id) : (int)strlen(id);
  const char *prefix = "rkmpm_sim_";
  for (size_t k = 0; k < sizeof library_functions / sizeof library_functions[0]; ++k) {
    if ((int)strlen(library_functions[k]) == n &&
        strncmp(id, library_functions[k], (size_t)n) == 0) {
      prefix = "rkmpm_";
    }
  }
  snprintf(row_function, sizeof row_function, "%s%.*s", prefix, n, id);
  return 1;
}

static int row_end(void) {
  if (row_problems == 0) {
    printf("ok %s\n", row_id);
    ++rows_ok;
  } else {
    printf("FAIL %s\n", row_id);
    ++rows_failed;
  }
  return 0;
}

/* One row of the table: the block runs once. */
#define ROW(id, want)                                                                              \
  for (int row_once_ = row_begin((id), (want)); row_once_; row_once_ = row_end())

/* Sets the last error to a message of another function than the row's. */
static void prime(void) {
  if (strcmp(row_function, "rkmpm_sim_time") == 0) {
    (void)rkmpm_sim_dim(NULL, NULL);
  } else {
    (void)rkmpm_sim_time(NULL, NULL);
  }
}

/* Checks a result against the row: the status, and for a failure the message `message` (of the
   thread that made the call). */
static void check_result(RkmpmStatus got, const char *message, const char *call, int line) {
  if ((int)got != row_want) {
    problem(line, "%s returned %d (%s), expected %d (%s); last message: %s", call, (int)got,
            rkmpm_status_str((int32_t)got), row_want, rkmpm_status_str((int32_t)row_want),
            message);
  } else if (got != RKMPM_OK) {
    const size_t n = strlen(row_function);
    if (strncmp(message, row_function, n) != 0 || strncmp(message + n, ": ", 2) != 0 ||
        message[n + 2] == '\0') {
      problem(line, "%s gave status %d, but the message \"%s\" is not \"%s: <text>\"", call,
              (int)got, message, row_function);
    } else if (verbose) {
      printf("  %s: %s\n", row_id, message);
    }
  }
}

static void check_status(RkmpmStatus got, const char *call, int line) {
  char *message = rkmpm_example_last_error();
  check_result(got, message, call, line);
  free(message);
}

static void expect_unchanged(Snapshot *before, const RkmpmSim *sim, const char *call, int line) {
  Snapshot after = snapshot_take(sim);
  char what[256];
  if (!snapshot_compare(before, &after, what, sizeof what)) {
    problem(line, "%s changed the simulation: %s", call, what);
  }
  snapshot_release(&after);
}

/* Calls `call` (an RkmpmStatus expression) and checks the row's status and message; when `sim`
   is not NULL, also that the call left that simulation unchanged. */
#define CALL(sim, call)                                                                            \
  do {                                                                                             \
    const RkmpmSim *call_sim_ = (sim);                                                             \
    Snapshot call_before_;                                                                         \
    memset(&call_before_, 0, sizeof call_before_);                                                 \
    if (call_sim_ != NULL) {                                                                       \
      call_before_ = snapshot_take(call_sim_);                                                     \
    }                                                                                              \
    prime();                                                                                       \
    const RkmpmStatus call_got_ = (call);                                                          \
    check_status(call_got_, #call, __LINE__);                                                      \
    if (call_sim_ != NULL) {                                                                       \
      expect_unchanged(&call_before_, call_sim_, #call, __LINE__);                                 \
    }                                                                                              \
    snapshot_release(&call_before_);                                                               \
  } while (0)

/* ---- fixtures ---------------------------------------------------------------------------- */

static const double H = 0.1;
static const double ORIGIN[3] = {0.0, 0.0, 0.0};
static const size_t CELLS[3] = {10, 10, 10};

typedef struct {
  RkmpmSim *sim;
  uint32_t dim;
  uint32_t material; /* the block's material */
  uint32_t materials; /* how many materials were added */
  size_t count;
} Fixture;

/* A grid of 10^dim cells of 0.1 from the origin, no materials, no particles. */
static Fixture empty_sim(uint32_t dim) {
  Fixture f;
  memset(&f, 0, sizeof f);
  f.dim = dim;
  RKMPM_CHECK(rkmpm_sim_new(dim, ORIGIN, CELLS, H, &f.sim));
  return f;
}

/* The grid of empty_sim with 4^dim moving particles of one linear elastic material at spacing
   h/2 on [0.4, 0.6]^dim. */
static Fixture block_with(uint32_t dim, double density, double young) {
  Fixture f = empty_sim(dim);
  RKMPM_CHECK(rkmpm_sim_add_material_linear_elastic(f.sim, density, young, 0.3, &f.material));
  f.materials = 1;
  double x[64 * 3], v[64 * 3], vol[64];
  const size_t n = dim == 2 ? 16 : 64;
  for (size_t p = 0; p < n; ++p) {
    const size_t i[3] = {p % 4, (p / 4) % 4, p / 16};
    for (uint32_t d = 0; d < dim; ++d) {
      x[dim * p + d] = 0.4 + ((double)i[d] + 0.5) * H / 2.0;
    }
    v[dim * p] = 0.05 * (1.0 + 0.1 * (double)i[1]);
    v[dim * p + 1] = -0.025;
    if (dim == 3) {
      v[dim * p + 2] = 0.01 * (double)i[0];
    }
    vol[p] = dim == 2 ? H * H / 4.0 : H * H * H / 8.0;
  }
  RKMPM_CHECK(rkmpm_sim_add_particles(f.sim, f.material, n, x, vol, v));
  f.count = n;
  return f;
}

static Fixture block(uint32_t dim) { return block_with(dim, 1.0, 100.0); }

static double stable_dt(const Fixture *f, double cfl) {
  double dt = 0.0;
  RKMPM_CHECK(rkmpm_sim_stable_dt(f->sim, cfl, &dt));
  return dt;
}

static void take_step(Fixture *f) { RKMPM_CHECK(rkmpm_sim_step(f->sim, stable_dt(f, 0.5))); }

/* Progress callback: counts its calls, records the last report, stops at call `stop_at`. */
typedef struct {
  int calls;
  int stop_at;
  uint64_t steps;
  double time, end_time;
} ProgressData;

static int32_t progress(void *user_data, uint64_t steps, double time, double end_time, double dt) {
  ProgressData *data = user_data;
  ++data->calls;
  data->steps = steps;
  data->time = time;
  data->end_time = end_time;
  return (dt <= 0.0 || data->calls == data->stop_at) ? 1 : 0;
}

/* A block that has taken one step. */
static Fixture stepped_block(uint32_t dim) {
  Fixture f = block(dim);
  take_step(&f);
  return f;
}

/* A 2D block of 16 particles at rest whose simulation has reached the time `t` (by one step
   taken before there were particles). */
static Fixture resting_block_at(double t) {
  Fixture f = empty_sim(2);
  RKMPM_CHECK(rkmpm_sim_step(f.sim, t));
  RKMPM_CHECK(rkmpm_sim_add_material_linear_elastic(f.sim, 1.0, 100.0, 0.3, &f.material));
  f.materials = 1;
  double x[32], vol[16];
  for (size_t p = 0; p < 16; ++p) {
    x[2 * p] = 0.4 + ((double)(p % 4) + 0.5) * H / 2.0;
    x[2 * p + 1] = 0.4 + ((double)(p / 4) + 0.5) * H / 2.0;
    vol[p] = H * H / 4.0;
  }
  RKMPM_CHECK(rkmpm_sim_add_particles(f.sim, f.material, 16, x, vol, NULL));
  f.count = 16;
  return f;
}

static void drop(Fixture *f) {
  rkmpm_sim_free(f->sim);
  f->sim = NULL;
}

/* A rejected material wrote no id and used up none: the next material gets the next id. */
static void expect_material_rejected(Fixture *f, uint32_t id, int line) {
  if (id != 77) {
    problem(line, "a rejected material wrote the id %u", (unsigned)id);
  }
  uint32_t next = 99;
  RKMPM_CHECK(rkmpm_sim_add_material_linear_elastic(f->sim, 1.0, 100.0, 0.3, &next));
  if (next != f->materials) {
    problem(line, "after a rejected material the next id is %u, expected %u", (unsigned)next,
            (unsigned)f->materials);
  }
  f->materials += 1;
}

/* A pointer one byte past `p`: misaligned for every type but char. The library checks the
   alignment before it reads or writes anything. */
static void *misaligned(const void *p) { return (void *)((uintptr_t)p + 1); }

/* ---- materials (one call per row, on a fresh block) -------------------------------------- */

static void linear_elastic_rejects(double density, double young, double poisson) {
  Fixture f = block(2);
  uint32_t id = 77;
  CALL(f.sim, rkmpm_sim_add_material_linear_elastic(f.sim, density, young, poisson, &id));
  expect_material_rejected(&f, id, __LINE__);
  drop(&f);
}

static void neo_hookean_rejects(double density, double young, double poisson) {
  Fixture f = block(2);
  uint32_t id = 77;
  CALL(f.sim, rkmpm_sim_add_material_neo_hookean(f.sim, density, young, poisson, &id));
  expect_material_rejected(&f, id, __LINE__);
  drop(&f);
}

static void drucker_prager_rejects(double density, double young, double poisson, double friction,
                                   double cohesion, double dilatancy) {
  Fixture f = block(2);
  uint32_t id = 77;
  CALL(f.sim, rkmpm_sim_add_material_drucker_prager(f.sim, density, young, poisson, friction,
                                                    cohesion, dilatancy, &id));
  expect_material_rejected(&f, id, __LINE__);
  drop(&f);
}

/* The μ(I) rheology refused for a Drucker-Prager material of a block. */
static void rheology_rejects(uint32_t enabled, double friction_increase, double inertial_number,
                             double grain_diameter) {
  Fixture f = block(2);
  uint32_t soil = 77;
  RKMPM_CHECK(rkmpm_sim_add_material_drucker_prager(f.sim, 2650.0, 1e6, 0.3, 30.0, 0.0, 0.0, &soil));
  CALL(f.sim, rkmpm_sim_set_drucker_prager_rheology(f.sim, soil, enabled, friction_increase,
                                                    inertial_number, grain_diameter));
  drop(&f);
}

/* OFHC copper with damage and the Mie-Grueneisen EOS: a valid parameter set. */
static RkmpmJohnsonCook copper(void) {
  RkmpmJohnsonCook p = {
      .density = 8960.0,
      .young = 124e9,
      .poisson = 0.34,
      .a = 90e6,
      .b = 292e6,
      .n = 0.31,
      .c = 0.025,
      .reference_strain_rate = 1.0,
      .m = 1.09,
      .room_temperature = 298.0,
      .melt_temperature = 1356.0,
      .specific_heat = 383.0,
      .taylor_quinney = 0.9,
      .damage_enabled = 1,
      .d1 = 0.54,
      .d2 = 4.89,
      .d3 = -3.03,
      .d4 = 0.014,
      .d5 = 1.12,
      .eos_enabled = 1,
      .eos_sound_speed = 3940.0,
      .eos_slope = 1.49,
      .eos_gamma0 = 2.02,
  };
  return p;
}

static void johnson_cook_rejects(RkmpmJohnsonCook p) {
  Fixture f = block(2);
  uint32_t id = 77;
  CALL(f.sim, rkmpm_sim_add_material_johnson_cook(f.sim, &p, &id));
  expect_material_rejected(&f, id, __LINE__);
  drop(&f);
}

static void rigid_rejects(uint32_t dim, double density, const double *velocity) {
  Fixture f = block(dim);
  uint32_t id = 77;
  CALL(f.sim, rkmpm_sim_add_material_rigid(f.sim, density, velocity, &id));
  expect_material_rejected(&f, id, __LINE__);
  drop(&f);
}

/* A rigid body (material 1, moving at 0.5 along x) beside the fixture's elastic material 0, and
   `rkmpm_sim_set_rigid_velocity` on `material` with `velocity`. */
static void rigid_velocity_rejects(uint32_t dim, uint32_t material, const double *velocity) {
  Fixture f = block(dim);
  const double v0[3] = {0.5, 0.0, 0.0};
  uint32_t plate = 77;
  RKMPM_CHECK(rkmpm_sim_add_material_rigid(f.sim, 1000.0, v0, &plate));
  CALL(f.sim, rkmpm_sim_set_rigid_velocity(f.sim, material, velocity));
  drop(&f);
}

/* ---- particles and boundary points ---------------------------------------------------------- */

/* Two 2D particles, the first one valid: all or nothing. */
static void particles_reject(const double x[4], const double vol[2], const double *v) {
  Fixture f = block(2);
  CALL(f.sim, rkmpm_sim_add_particles(f.sim, f.material, 2, x, vol, v));
  drop(&f);
}

static void boundary_points_reject(const double x[4], const double n[4], const double *t) {
  Fixture f = block(2);
  CALL(f.sim, rkmpm_sim_add_boundary_points(f.sim, 2, x, n, t));
  drop(&f);
}

/* ---- body-force callbacks ------------------------------------------------------------------ */

enum ForceMode {
  FORCE_COUNT,        /* writes zeros */
  FORCE_RETURN_ERROR, /* returns 1 */
  FORCE_WRITE_NAN,    /* writes NaN for one particle */
  FORCE_WRITE_INF,    /* writes +inf for one particle */
  FORCE_HUGE,         /* DBL_MAX along x for every particle: finite, the grid forces overflow */
  FORCE_CONVERGE,     /* a = -k (x - c) along x: the block folds over within one step */
  FORCE_FAIL_THIRD    /* writes zeros for two calls, then returns 1 */
};

typedef struct {
  enum ForceMode mode;
  int calls;
  double k, center;
} ForceData;

static int32_t body_force(void *user_data, double time, size_t count, uint32_t dim,
                          const double *reference_positions, const double *positions,
                          double *accelerations) {
  ForceData *data = user_data;
  (void)time;
  (void)reference_positions;
  ++data->calls;
  for (size_t i = 0; i < count * dim; ++i) {
    accelerations[i] = 0.0;
  }
  switch (data->mode) {
  case FORCE_COUNT:
    return 0;
  case FORCE_RETURN_ERROR:
    return 1;
  case FORCE_WRITE_NAN:
    accelerations[dim * (count / 2)] = NAN;
    return 0;
  case FORCE_WRITE_INF:
    accelerations[dim * (count / 2) + 1] = INFINITY;
    return 0;
  case FORCE_HUGE:
    for (size_t p = 0; p < count; ++p) {
      accelerations[p * dim] = DBL_MAX;
    }
    return 0;
  case FORCE_CONVERGE:
    for (size_t p = 0; p < count; ++p) {
      accelerations[p * dim] = -data->k * (positions[p * dim] - data->center);
    }
    return 0;
  case FORCE_FAIL_THIRD:
    return data->calls >= 3 ? 1 : 0;
  }
  return 2;
}

/* ---- files ---------------------------------------------------------------------------------- */

static const char *scratch_dir = ".";

/* `<scratch>/<name>` in one of four rotating buffers. */
static const char *scratch(const char *name) {
  static char buffers[4][1024];
  static int next = 0;
  char *b = buffers[next];
  next = (next + 1) % 4;
  snprintf(b, sizeof buffers[0], "%s/%s", scratch_dir, name);
  return b;
}

static int file_exists(const char *path) {
  FILE *f = fopen(path, "rb");
  if (f != NULL) {
    fclose(f);
    return 1;
  }
  return 0;
}

static unsigned char *read_file(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (f == NULL) {
    fprintf(stderr, "cannot read %s\n", path);
    exit(EXIT_FAILURE);
  }
  size_t cap = 1 << 16, n = 0;
  unsigned char *b = malloc(cap);
  for (;;) {
    if (b == NULL) {
      fprintf(stderr, "out of memory\n");
      exit(EXIT_FAILURE);
    }
    n += fread(b + n, 1, cap - n, f);
    if (n < cap) {
      break;
    }
    cap *= 2;
    b = realloc(b, cap);
  }
  fclose(f);
  *len = n;
  return b;
}

/* Whether the file at `path` holds the bytes of `text` (binary files too). */
static int file_contains(const char *path, const char *text) {
  size_t len = 0, k = strlen(text);
  unsigned char *b = read_file(path, &len);
  int found = 0;
  for (size_t i = 0; !found && i + k <= len; i++) {
    found = memcmp(b + i, text, k) == 0;
  }
  free(b);
  return found;
}

static void write_file(const char *path, const unsigned char *bytes, size_t len) {
  FILE *f = fopen(path, "wb");
  if (f == NULL || fwrite(bytes, 1, len, f) != len || fclose(f) != 0) {
    fprintf(stderr, "cannot write %s\n", path);
    exit(EXIT_FAILURE);
  }
}

static uint32_t crc32(const unsigned char *p, size_t n) {
  uint32_t c = 0xFFFFFFFFu;
  for (size_t i = 0; i < n; ++i) {
    c ^= p[i];
    for (int k = 0; k < 8; ++k) {
      c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
    }
  }
  return ~c;
}

/* Checkpoint frame: magic (8), version (4), dimension (4), payload length (8), payload, CRC-32 of
   the payload (4), little-endian. Rewrites the length and the checksum after an edit. */
static void reframe(unsigned char *bytes, size_t len) {
  const uint64_t payload = len - 28;
  for (int k = 0; k < 8; ++k) {
    bytes[16 + k] = (unsigned char)(payload >> (8 * k));
  }
  const uint32_t c = crc32(bytes + 24, len - 28);
  for (int k = 0; k < 4; ++k) {
    bytes[len - 4 + k] = (unsigned char)(c >> (8 * k));
  }
}

/* Loads `path`, which must be refused with the row's status and give no handle. */
static void load_refuses(const char *path) {
  RkmpmSim *out = (RkmpmSim *)(uintptr_t)&rows_ok;
  CALL(NULL, rkmpm_sim_load(path, &out));
  EXPECT(out == NULL, "a refused load must write NULL to *out");
  if (out != NULL && out != (RkmpmSim *)(uintptr_t)&rows_ok) {
    /* Loaded although it should not have: show what its first step does, then release it. */
    double dt = 0.0;
    RkmpmStatus s = rkmpm_sim_stable_dt(out, 0.5, &dt);
    if (s == RKMPM_OK) {
      s = rkmpm_sim_step(out, dt);
    }
    char *message = rkmpm_example_last_error();
    fprintf(stderr, "  the loaded simulation's first step gave %d (%s): %s\n", (int)s,
            rkmpm_status_str((int32_t)s), s == RKMPM_OK ? "" : message);
    free(message);
    rkmpm_sim_free(out);
  }
}

/* ---- threads --------------------------------------------------------------------------------- */

static int fresh_thread(void *arg) {
  size_t *result = arg;
  char buf[8] = "XXXXXXX";
  result[0] = rkmpm_last_error_message(buf, sizeof buf);
  result[1] = buf[0] == '\0';
  return 0;
}

/* ============================================================================================ */

static void library_rows(void) {
  ROW("version.static_string", NO_STATUS) {
    const char *v = rkmpm_version();
    EXPECT(v != NULL && v[0] != '\0', "empty version string");
    EXPECT(rkmpm_version() == v, "the version string is not static");
  }
  ROW("abi_version.matches_header", NO_STATUS) {
    EXPECT(rkmpm_abi_version() == RKMPM_ABI_VERSION, "ABI %u, header %u",
           (unsigned)rkmpm_abi_version(), (unsigned)RKMPM_ABI_VERSION);
  }
  /* The known statuses are 0 .. last, without gaps; at least 0 .. 14. */
  int32_t last = -1;
  while (last < 1000 && strcmp(rkmpm_status_str(last + 1), "unknown status") != 0) {
    ++last;
  }
  ROW("status_str.known", NO_STATUS) {
    EXPECT(last >= 14, "only the statuses 0 .. %d are known", (int)last);
    for (int32_t s = 0; s <= last; ++s) {
      const char *name = rkmpm_status_str(s);
      EXPECT(name != NULL && name[0] != '\0', "status %d has no string", (int)s);
      for (int32_t t = 0; name != NULL && t < s; ++t) {
        EXPECT(strcmp(name, rkmpm_status_str(t)) != 0, "statuses %d and %d share a string",
               (int)t, (int)s);
      }
    }
  }
  ROW("status_str.unknown", NO_STATUS) {
    const int32_t unknown[] = {last + 1, last + 2, 99, -1, INT32_MIN, INT32_MAX};
    for (size_t k = 0; k < sizeof unknown / sizeof unknown[0]; ++k) {
      const char *s = rkmpm_status_str(unknown[k]);
      EXPECT(s != NULL && strcmp(s, "unknown status") == 0, "status %ld gives \"%s\"",
             (long)unknown[k], s != NULL ? s : "(null)");
    }
  }

  /* The message of the last failure: "rkmpm_sim_step: sim is NULL". */
  const char *const message = "rkmpm_sim_step: sim is NULL";
  const size_t full = strlen(message);
  ROW("last_error_message.null_buf", NO_STATUS) {
    (void)rkmpm_sim_step(NULL, 1.0);
    EXPECT(rkmpm_last_error_message(NULL, 100) == full, "NULL buffer: wrong length");
    EXPECT(rkmpm_last_error_message(NULL, 0) == full, "NULL buffer, len 0: wrong length");
  }
  ROW("last_error_message.zero_len", NO_STATUS) {
    (void)rkmpm_sim_step(NULL, 1.0);
    char buf[4] = "XYZ";
    EXPECT(rkmpm_last_error_message(buf, 0) == full, "len 0: wrong length");
    EXPECT(strcmp(buf, "XYZ") == 0, "len 0 wrote into the buffer");
  }
  ROW("last_error_message.short_buf", NO_STATUS) {
    (void)rkmpm_sim_step(NULL, 1.0);
    char buf[9];
    memset(buf, 'X', sizeof buf);
    EXPECT(rkmpm_last_error_message(buf, 8) == full, "short buffer: wrong length");
    EXPECT(buf[7] == '\0' && memcmp(buf, message, 7) == 0 && buf[8] == 'X',
           "short buffer: not the first 7 bytes and a NUL");
    char one = 'X';
    EXPECT(rkmpm_last_error_message(&one, 1) == full && one == '\0', "1-byte buffer: not a NUL");
  }
  ROW("last_error_message.huge_len", NO_STATUS) {
    (void)rkmpm_sim_step(NULL, 1.0);
    char buf[256];
    memset(buf, 'X', sizeof buf);
    EXPECT(rkmpm_last_error_message(buf, SIZE_MAX) == full, "huge len: wrong length");
    EXPECT(strcmp(buf, message) == 0 && buf[full + 1] == 'X',
           "huge len: wrote more than the message and its NUL");
  }
  ROW("last_error_message.fresh_thread", NO_STATUS) {
    (void)rkmpm_sim_step(NULL, 1.0);
    size_t result[2] = {99, 0};
    thrd_t thread;
    EXPECT(thrd_create(&thread, fresh_thread, result) == thrd_success, "thrd_create");
    thrd_join(thread, NULL);
    EXPECT(result[0] == 0 && result[1] == 1, "a new thread sees a message of length %zu",
           result[0]);
  }
}

static void lifetime_rows(void) {
  RkmpmSim *const sentinel = (RkmpmSim *)(uintptr_t)&rows_ok;
  RkmpmSim *out = sentinel;
  _Alignas(8) unsigned char raw[64] = {0};

  ROW("new.null_out", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_new(2, ORIGIN, CELLS, H, NULL));
  }
  ROW("new.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    CALL(NULL, rkmpm_sim_new(2, ORIGIN, CELLS, H, misaligned(raw)));
    EXPECT(raw[1] == 0 && raw[8] == 0, "wrote through a misaligned out pointer");
  }
  ROW("new.null_origin", RKMPM_ERR_NULL_POINTER) {
    out = sentinel;
    CALL(NULL, rkmpm_sim_new(2, NULL, CELLS, H, &out));
    EXPECT(out == NULL, "*out must be NULL after a failure");
  }
  ROW("new.null_cells", RKMPM_ERR_NULL_POINTER) {
    out = sentinel;
    CALL(NULL, rkmpm_sim_new(3, ORIGIN, NULL, H, &out));
    EXPECT(out == NULL, "*out must be NULL after a failure");
  }
  ROW("new.misaligned_origin", RKMPM_ERR_INVALID_ARGUMENT) {
    out = sentinel;
    CALL(NULL, rkmpm_sim_new(2, misaligned(raw), CELLS, H, &out));
    EXPECT(out == NULL, "*out must be NULL after a failure");
  }
  ROW("new.misaligned_cells", RKMPM_ERR_INVALID_ARGUMENT) {
    out = sentinel;
    CALL(NULL, rkmpm_sim_new(2, ORIGIN, misaligned(raw), H, &out));
    EXPECT(out == NULL, "*out must be NULL after a failure");
  }
  ROW("new.bad_dim", RKMPM_ERR_INVALID_ARGUMENT) {
    const uint32_t dims[] = {0, 1, 4, UINT32_MAX};
    for (size_t k = 0; k < 4; ++k) {
      out = sentinel;
      CALL(NULL, rkmpm_sim_new(dims[k], ORIGIN, CELLS, H, &out));
      EXPECT(out == NULL, "*out must be NULL after a failure");
    }
  }
  ROW("new.cell_size_not_positive", RKMPM_ERR_INVALID_ARGUMENT) {
    const double h[] = {0.0, -0.0, -0.1, -INFINITY};
    for (size_t k = 0; k < 4; ++k) {
      out = sentinel;
      CALL(NULL, rkmpm_sim_new(2, ORIGIN, CELLS, h[k], &out));
      EXPECT(out == NULL, "*out must be NULL after a failure");
    }
  }
  ROW("new.cell_size_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    out = sentinel;
    CALL(NULL, rkmpm_sim_new(3, ORIGIN, CELLS, NAN, &out));
    EXPECT(out == NULL, "*out must be NULL after a failure");
  }
  ROW("new.cell_size_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    out = sentinel;
    CALL(NULL, rkmpm_sim_new(2, ORIGIN, CELLS, INFINITY, &out));
    EXPECT(out == NULL, "*out must be NULL after a failure");
  }
  ROW("new.origin_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    const double o[3] = {0.0, 0.0, NAN};
    out = sentinel;
    CALL(NULL, rkmpm_sim_new(3, o, CELLS, H, &out));
    EXPECT(out == NULL, "*out must be NULL after a failure");
  }
  ROW("new.origin_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    const double o[2] = {-INFINITY, 0.0};
    out = sentinel;
    CALL(NULL, rkmpm_sim_new(2, o, CELLS, H, &out));
    EXPECT(out == NULL, "*out must be NULL after a failure");
  }
  ROW("new.zero_cells", RKMPM_ERR_INVALID_ARGUMENT) {
    const size_t c[3] = {10, 10, 0};
    out = sentinel;
    CALL(NULL, rkmpm_sim_new(3, ORIGIN, c, H, &out));
    EXPECT(out == NULL, "*out must be NULL after a failure");
  }
  ROW("new.huge_cells", RKMPM_ERR_INVALID_ARGUMENT) {
    const size_t c[2][2] = {{SIZE_MAX, 10}, {10, (1u << 24) + 1}};
    for (size_t k = 0; k < 2; ++k) {
      out = sentinel;
      CALL(NULL, rkmpm_sim_new(2, ORIGIN, c[k], H, &out));
      EXPECT(out == NULL, "*out must be NULL after a failure");
    }
  }
  ROW("new.too_many_nodes", RKMPM_ERR_INVALID_ARGUMENT) {
    const size_t c[3] = {1u << 24, 1u << 24, 1u << 24};
    out = sentinel;
    CALL(NULL, rkmpm_sim_new(2, ORIGIN, c, H, &out));
    EXPECT(out == NULL, "*out must be NULL after a failure");
    out = sentinel;
    CALL(NULL, rkmpm_sim_new(3, ORIGIN, c, H, &out));
    EXPECT(out == NULL, "*out must be NULL after a failure");
  }
  ROW("new.domain_overflow", RKMPM_ERR_INVALID_ARGUMENT) {
    const double o[2] = {1e308, 0.0};
    const size_t c[2] = {10, 10};
    out = sentinel;
    CALL(NULL, rkmpm_sim_new(2, o, c, 1e307, &out));
    EXPECT(out == NULL, "*out must be NULL after a failure");
  }

  ROW("free.null", NO_STATUS) {
    rkmpm_sim_free(NULL); /* a no-op: nothing to check but that it returns */
  }

  ROW("dim.null_sim", RKMPM_ERR_NULL_POINTER) {
    uint32_t dim = 77;
    CALL(NULL, rkmpm_sim_dim(NULL, &dim));
    EXPECT(dim == 77, "wrote the output after a failure");
  }
  ROW("dim.misaligned_sim", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    uint32_t dim = 77;
    CALL(f.sim, rkmpm_sim_dim(misaligned(f.sim), &dim));
    EXPECT(dim == 77, "wrote the output after a failure");
    drop(&f);
  }
  ROW("dim.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(3);
    CALL(f.sim, rkmpm_sim_dim(f.sim, NULL));
    drop(&f);
  }
  ROW("dim.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_dim(f.sim, misaligned(raw)));
    drop(&f);
  }

  ROW("particle_count.null_sim", NO_STATUS) {
    EXPECT(rkmpm_sim_particle_count(NULL) == 0, "the particle count of NULL is not 0");
  }

  ROW("boundary_point_count.null_sim", RKMPM_ERR_NULL_POINTER) {
    size_t n = 77;
    CALL(NULL, rkmpm_sim_boundary_point_count(NULL, &n));
    EXPECT(n == 77, "wrote the output after a failure");
  }
  ROW("boundary_point_count.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_boundary_point_count(f.sim, NULL));
    drop(&f);
  }
  ROW("boundary_point_count.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_boundary_point_count(f.sim, misaligned(raw)));
    drop(&f);
  }

  ROW("time.null_sim", RKMPM_ERR_NULL_POINTER) {
    double t = 77.0;
    CALL(NULL, rkmpm_sim_time(NULL, &t));
    EXPECT(t == 77.0, "wrote the output after a failure");
  }
  ROW("time.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = stepped_block(2);
    CALL(f.sim, rkmpm_sim_time(f.sim, NULL));
    drop(&f);
  }
  ROW("time.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_time(f.sim, misaligned(raw)));
    drop(&f);
  }

  ROW("energies.null_sim", RKMPM_ERR_NULL_POINTER) {
    RkmpmEnergies e = {77.0, 77.0, 77.0};
    CALL(NULL, rkmpm_sim_energies(NULL, &e));
    EXPECT(e.kinetic == 77.0 && e.gravitational == 77.0, "wrote the output after a failure");
  }
  ROW("energies.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = stepped_block(2);
    CALL(f.sim, rkmpm_sim_energies(f.sim, NULL));
    drop(&f);
  }
  ROW("energies.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = stepped_block(2);
    memset(raw, 0, sizeof raw);
    CALL(f.sim, rkmpm_sim_energies(f.sim, misaligned(raw)));
    EXPECT(raw[1] == 0 && raw[9] == 0, "wrote through a misaligned out pointer");
    drop(&f);
  }
  ROW("set_energy_accounting.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_energy_accounting(NULL, 1));
  }
  ROW("set_energy_accounting.bad_flag", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = stepped_block(2);
    RkmpmEnergyBalance b;
    CALL(f.sim, rkmpm_sim_set_energy_accounting(f.sim, 2));
    CALL(f.sim, rkmpm_sim_set_energy_accounting(f.sim, UINT32_MAX));
    EXPECT(rkmpm_sim_energy_balance(f.sim, &b) == RKMPM_ERR_INVALID_STATE,
           "a refused flag switched the accounting on");
    drop(&f);
  }
  ROW("energy_balance.null_sim", RKMPM_ERR_NULL_POINTER) {
    RkmpmEnergyBalance b = {77.0, 77.0, 77.0, 77.0, 77.0, 77.0, 77.0, 77.0, 77.0, 77.0};
    CALL(NULL, rkmpm_sim_energy_balance(NULL, &b));
    EXPECT(b.kinetic == 77.0 && b.other_dissipation == 77.0, "wrote the output after a failure");
  }
  ROW("energy_balance.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = stepped_block(2);
    EXPECT(rkmpm_sim_set_energy_accounting(f.sim, 1) == RKMPM_OK, "accounting refused");
    CALL(f.sim, rkmpm_sim_energy_balance(f.sim, NULL));
    drop(&f);
  }
  ROW("energy_balance.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = stepped_block(2);
    EXPECT(rkmpm_sim_set_energy_accounting(f.sim, 1) == RKMPM_OK, "accounting refused");
    memset(raw, 0, sizeof raw);
    CALL(f.sim, rkmpm_sim_energy_balance(f.sim, misaligned(raw)));
    EXPECT(raw[1] == 0 && raw[9] == 0, "wrote through a misaligned out pointer");
    drop(&f);
  }
  ROW("energy_balance.accounting_off", RKMPM_ERR_INVALID_STATE) {
    Fixture f = stepped_block(3);
    RkmpmEnergyBalance b = {77.0, 77.0, 77.0, 77.0, 77.0, 77.0, 77.0, 77.0, 77.0, 77.0};
    CALL(f.sim, rkmpm_sim_energy_balance(f.sim, &b));
    EXPECT(b.kinetic == 77.0 && b.start == 77.0, "wrote the output after a failure");
    drop(&f);
  }
  ROW("momenta.null_sim", RKMPM_ERR_NULL_POINTER) {
    RkmpmMomenta p = {{77.0, 77.0, 77.0}, {77.0, 77.0, 77.0}};
    CALL(NULL, rkmpm_sim_momenta(NULL, &p));
    EXPECT(p.linear[0] == 77.0 && p.angular[2] == 77.0, "wrote the output after a failure");
  }
  ROW("momenta.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = stepped_block(2);
    CALL(f.sim, rkmpm_sim_momenta(f.sim, NULL));
    drop(&f);
  }
  ROW("momenta.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = stepped_block(3);
    memset(raw, 0, sizeof raw);
    CALL(f.sim, rkmpm_sim_momenta(f.sim, misaligned(raw)));
    EXPECT(raw[1] == 0 && raw[9] == 0, "wrote through a misaligned out pointer");
    drop(&f);
  }

  ROW("step_count.null_sim", RKMPM_ERR_NULL_POINTER) {
    uint64_t n = 77;
    CALL(NULL, rkmpm_sim_step_count(NULL, &n));
    EXPECT(n == 77, "wrote the output after a failure");
  }
  ROW("step_count.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = stepped_block(2);
    CALL(f.sim, rkmpm_sim_step_count(f.sim, NULL));
    drop(&f);
  }
  ROW("step_count.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_step_count(f.sim, misaligned(raw)));
    drop(&f);
  }
  ROW("set_max_steps_per_advance.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_max_steps_per_advance(NULL, 10));
  }
  ROW("set_max_steps_per_advance.zero", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    RKMPM_CHECK(rkmpm_sim_set_max_steps_per_advance(f.sim, 123));
    CALL(f.sim, rkmpm_sim_set_max_steps_per_advance(f.sim, 0));
    uint64_t bound = 0;
    RKMPM_CHECK(rkmpm_sim_max_steps_per_advance(f.sim, &bound));
    EXPECT(bound == 123, "the bound is %llu", (unsigned long long)bound);
    drop(&f);
  }
  ROW("max_steps_per_advance.null_sim", RKMPM_ERR_NULL_POINTER) {
    uint64_t n = 77;
    CALL(NULL, rkmpm_sim_max_steps_per_advance(NULL, &n));
    EXPECT(n == 77, "wrote the output after a failure");
  }
  ROW("max_steps_per_advance.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_max_steps_per_advance(f.sim, NULL));
    uint64_t bound = 0;
    RKMPM_CHECK(rkmpm_sim_max_steps_per_advance(f.sim, &bound));
    EXPECT(bound == RKMPM_DEFAULT_MAX_STEPS_PER_ADVANCE, "the default bound is %llu",
           (unsigned long long)bound);
    drop(&f);
  }
  ROW("max_steps_per_advance.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_max_steps_per_advance(f.sim, misaligned(raw)));
    drop(&f);
  }
  ROW("set_vc_solve.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_vc_solve(NULL, 1e-6, 10));
  }
  ROW("set_vc_solve.bad_tolerance", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    RKMPM_CHECK(rkmpm_sim_set_vc_solve(f.sim, 1e-6, 10));
    CALL(f.sim, rkmpm_sim_set_vc_solve(f.sim, 0.0, 10));
    CALL(f.sim, rkmpm_sim_set_vc_solve(f.sim, -1e-4, 10));
    CALL(f.sim, rkmpm_sim_set_vc_solve(f.sim, 1.5, 10));
    CALL(f.sim, rkmpm_sim_set_vc_solve(f.sim, NAN, 10));
    CALL(f.sim, rkmpm_sim_set_vc_solve(f.sim, INFINITY, 10));
    double tolerance = 0.0;
    uint64_t iterations = 0;
    RKMPM_CHECK(rkmpm_sim_vc_solve(f.sim, &tolerance, &iterations));
    EXPECT(tolerance == 1e-6 && iterations == 10, "the rule is %g, %llu", tolerance,
           (unsigned long long)iterations);
    drop(&f);
  }
  ROW("set_vc_solve.zero_iterations", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_vc_solve(f.sim, 1e-6, 0));
    double tolerance = 0.0;
    uint64_t iterations = 0;
    RKMPM_CHECK(rkmpm_sim_vc_solve(f.sim, &tolerance, &iterations));
    EXPECT(tolerance == RKMPM_DEFAULT_VC_SOLVE_TOLERANCE &&
               iterations == RKMPM_DEFAULT_VC_SOLVE_MAX_ITERATIONS,
           "the rule is %g, %llu", tolerance, (unsigned long long)iterations);
    drop(&f);
  }
  ROW("vc_solve.null_sim", RKMPM_ERR_NULL_POINTER) {
    double tolerance = 7.0;
    uint64_t iterations = 77;
    CALL(NULL, rkmpm_sim_vc_solve(NULL, &tolerance, &iterations));
    EXPECT(tolerance == 7.0 && iterations == 77, "wrote the output after a failure");
  }
  ROW("vc_solve.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    double tolerance = 7.0;
    uint64_t iterations = 77;
    CALL(f.sim, rkmpm_sim_vc_solve(f.sim, NULL, &iterations));
    CALL(f.sim, rkmpm_sim_vc_solve(f.sim, &tolerance, NULL));
    EXPECT(tolerance == 7.0 && iterations == 77, "wrote one output after a failure");
    drop(&f);
  }
  ROW("vc_solve.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    double tolerance = 7.0;
    uint64_t iterations = 77;
    CALL(f.sim, rkmpm_sim_vc_solve(f.sim, misaligned(raw), &iterations));
    CALL(f.sim, rkmpm_sim_vc_solve(f.sim, &tolerance, misaligned(raw)));
    EXPECT(tolerance == 7.0 && iterations == 77, "wrote one output after a failure");
    drop(&f);
  }
  ROW("set_vc_solve_interval.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_vc_solve_interval(NULL, 2));
  }
  ROW("set_vc_solve_interval.zero", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    RKMPM_CHECK(rkmpm_sim_set_vc_solve_interval(f.sim, 3));
    CALL(f.sim, rkmpm_sim_set_vc_solve_interval(f.sim, 0));
    uint32_t steps = 0;
    RKMPM_CHECK(rkmpm_sim_vc_solve_interval(f.sim, &steps));
    EXPECT(steps == 3, "the interval is %u", (unsigned)steps);
    drop(&f);
  }
  ROW("vc_solve_interval.null_sim", RKMPM_ERR_NULL_POINTER) {
    uint32_t steps = 77;
    CALL(NULL, rkmpm_sim_vc_solve_interval(NULL, &steps));
    EXPECT(steps == 77, "wrote the output after a failure");
  }
  ROW("vc_solve_interval.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_vc_solve_interval(f.sim, NULL));
    uint32_t steps = 0;
    RKMPM_CHECK(rkmpm_sim_vc_solve_interval(f.sim, &steps));
    /* The automatic rule of the default shape, the quadratic B-spline, at order 1. */
    EXPECT(steps == RKMPM_BSPLINE_VC_SOLVE_INTERVAL, "the default interval is %u",
           (unsigned)steps);
    drop(&f);
  }
  ROW("vc_solve_interval.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_vc_solve_interval(f.sim, misaligned(raw)));
    drop(&f);
  }
  ROW("set_vc_surface_refresh.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_vc_surface_refresh(NULL, 2));
  }
  ROW("set_vc_surface_refresh.zero", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    RKMPM_CHECK(rkmpm_sim_set_vc_surface_refresh(f.sim, 3));
    CALL(f.sim, rkmpm_sim_set_vc_surface_refresh(f.sim, 0));
    uint32_t steps = 0;
    RKMPM_CHECK(rkmpm_sim_vc_surface_refresh(f.sim, &steps));
    EXPECT(steps == 3, "the interval is %u", (unsigned)steps);
    drop(&f);
  }
  ROW("vc_surface_refresh.null_sim", RKMPM_ERR_NULL_POINTER) {
    uint32_t steps = 77;
    CALL(NULL, rkmpm_sim_vc_surface_refresh(NULL, &steps));
    EXPECT(steps == 77, "wrote the output after a failure");
  }
  ROW("vc_surface_refresh.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_vc_surface_refresh(f.sim, NULL));
    uint32_t steps = 0;
    RKMPM_CHECK(rkmpm_sim_vc_surface_refresh(f.sim, &steps));
    EXPECT(steps == RKMPM_DEFAULT_VC_SURFACE_REFRESH, "the default interval is %u",
           (unsigned)steps);
    drop(&f);
  }
  ROW("vc_surface_refresh.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_vc_surface_refresh(f.sim, misaligned(raw)));
    drop(&f);
  }
  ROW("set_threads.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_threads(NULL, 2));
  }
  ROW("set_threads.too_many", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    RKMPM_CHECK(rkmpm_sim_set_threads(f.sim, 2));
    CALL(f.sim, rkmpm_sim_set_threads(f.sim, RKMPM_MAX_THREADS + 1));
    uint32_t threads = 0;
    RKMPM_CHECK(rkmpm_sim_threads(f.sim, &threads));
    EXPECT(threads == 2, "the simulation runs on %u threads", (unsigned)threads);
    drop(&f);
  }
  ROW("threads.null_sim", RKMPM_ERR_NULL_POINTER) {
    uint32_t threads = 77;
    CALL(NULL, rkmpm_sim_threads(NULL, &threads));
    EXPECT(threads == 77, "wrote the output after a failure");
  }
  ROW("threads.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_threads(f.sim, NULL));
    drop(&f);
  }
  ROW("threads.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_threads(f.sim, misaligned(raw)));
    drop(&f);
  }
}

static void option_rows(void) {
  /* ---- rkmpm_sim_set_shape ---- */
  ROW("set_shape.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_shape(NULL, RKMPM_SHAPE_LINEAR, 0, 0.0));
  }
  ROW("set_shape.unknown_shape", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_shape(f.sim, 4, 1, 2.0));
    CALL(f.sim, rkmpm_sim_set_shape(f.sim, UINT32_MAX, 0, 0.0));
    drop(&f);
  }
  ROW("set_shape.rk_order_out_of_range", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_RK, 0, 2.0));
    CALL(f.sim, rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_RK, 6, 4.0));
    CALL(f.sim, rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_RK, UINT32_MAX, 4.0));
    drop(&f);
  }
  ROW("set_shape.rk_support_out_of_range", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_RK, 1, 0.5));
    CALL(f.sim, rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_RK, 1, 8.01));
    CALL(f.sim, rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_RK, 1, -2.0));
    drop(&f);
  }
  ROW("set_shape.rk_support_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_RK, 1, NAN));
    drop(&f);
  }
  ROW("set_shape.rk_support_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_RK, 2, INFINITY));
    drop(&f);
  }
  ROW("set_shape.rk_support_ill_conditioned", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_RK, 2, 1.0));
    drop(&f);
  }
  ROW("set_shape.after_step", RKMPM_ERR_INVALID_STATE) {
    Fixture f = stepped_block(2);
    CALL(f.sim, rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_BSPLINE3, 0, 0.0));
    CALL(f.sim, rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_BSPLINE2, 0, 0.0)); /* even the same */
    drop(&f);
  }

  /* ---- rkmpm_sim_set_integration ---- */
  ROW("set_integration.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_integration(NULL, RKMPM_INTEGRATION_MP, 0));
  }
  ROW("set_integration.unknown_integration", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_integration(f.sim, 2, 1));
    CALL(f.sim, rkmpm_sim_set_integration(f.sim, UINT32_MAX, 1));
    drop(&f);
  }
  ROW("set_integration.vc_order_out_of_range", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_integration(f.sim, RKMPM_INTEGRATION_VC, 0));
    CALL(f.sim, rkmpm_sim_set_integration(f.sim, RKMPM_INTEGRATION_VC, 5));
    CALL(f.sim, rkmpm_sim_set_integration(f.sim, RKMPM_INTEGRATION_VC, UINT32_MAX));
    drop(&f);
  }
  ROW("set_integration.after_step", RKMPM_ERR_INVALID_STATE) {
    Fixture f = stepped_block(2);
    CALL(f.sim, rkmpm_sim_set_integration(f.sim, RKMPM_INTEGRATION_VC, 1));
    CALL(f.sim, rkmpm_sim_set_integration(f.sim, RKMPM_INTEGRATION_MP, 0));
    drop(&f);
  }

  /* ---- rkmpm_sim_set_transfer ---- */
  ROW("set_transfer.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_transfer(NULL, RKMPM_TRANSFER_APIC, 0.0));
  }
  ROW("set_transfer.unknown_transfer", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_transfer(f.sim, 3, 0.0));
    CALL(f.sim, rkmpm_sim_set_transfer(f.sim, UINT32_MAX, 0.0));
    drop(&f);
  }
  ROW("set_transfer.flip_out_of_range", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_transfer(f.sim, RKMPM_TRANSFER_PIC_FLIP, 1.0000001));
    CALL(f.sim, rkmpm_sim_set_transfer(f.sim, RKMPM_TRANSFER_PIC_FLIP, -0.1));
    drop(&f);
  }
  ROW("set_transfer.flip_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_transfer(f.sim, RKMPM_TRANSFER_PIC_FLIP, NAN));
    drop(&f);
  }
  ROW("set_transfer.flip_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_transfer(f.sim, RKMPM_TRANSFER_PIC_FLIP, INFINITY));
    CALL(f.sim, rkmpm_sim_set_transfer(f.sim, RKMPM_TRANSFER_PIC_FLIP, -INFINITY));
    drop(&f);
  }
  ROW("set_transfer.after_step", RKMPM_ERR_INVALID_STATE) {
    Fixture f = stepped_block(2);
    CALL(f.sim, rkmpm_sim_set_transfer(f.sim, RKMPM_TRANSFER_PIC_FLIP, 0.5));
    CALL(f.sim, rkmpm_sim_set_transfer(f.sim, RKMPM_TRANSFER_APIC, 0.0));
    drop(&f);
  }

  /* ---- rkmpm_sim_set_scheme ---- */
  ROW("set_scheme.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_scheme(NULL, RKMPM_SCHEME_USL));
  }
  ROW("set_scheme.unknown_scheme", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_scheme(f.sim, 2));
    CALL(f.sim, rkmpm_sim_set_scheme(f.sim, UINT32_MAX));
    drop(&f);
  }
  ROW("set_scheme.after_step", RKMPM_ERR_INVALID_STATE) {
    Fixture f = stepped_block(3);
    CALL(f.sim, rkmpm_sim_set_scheme(f.sim, RKMPM_SCHEME_MUSL));
    drop(&f);
  }

  /* ---- rkmpm_sim_set_contact ---- */
  ROW("set_contact.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_contact(NULL, 1, 0.2));
  }
  ROW("set_contact.bad_flag", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_contact(f.sim, 2, 0.2));
    CALL(f.sim, rkmpm_sim_set_contact(f.sim, UINT32_MAX, 0.2));
    drop(&f);
  }
  ROW("set_contact.friction_negative", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_contact(f.sim, 1, -0.1));
    drop(&f);
  }
  ROW("set_contact.friction_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_contact(f.sim, 1, NAN));
    drop(&f);
  }
  ROW("set_contact.friction_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_contact(f.sim, 1, INFINITY));
    drop(&f);
  }
  ROW("set_contact.after_step", RKMPM_ERR_INVALID_STATE) {
    Fixture f = stepped_block(2);
    CALL(f.sim, rkmpm_sim_set_contact(f.sim, 1, 0.2));
    CALL(f.sim, rkmpm_sim_set_contact(f.sim, 0, 0.0));
    drop(&f);
  }

  /* ---- rkmpm_sim_set_gravity ---- */
  ROW("set_gravity.null_sim", RKMPM_ERR_NULL_POINTER) {
    const double g[2] = {0.0, -9.81};
    CALL(NULL, rkmpm_sim_set_gravity(NULL, g));
  }
  ROW("set_gravity.null_g", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_gravity(f.sim, NULL));
    drop(&f);
  }
  ROW("set_gravity.misaligned_g", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    _Alignas(8) unsigned char raw[64] = {0};
    CALL(f.sim, rkmpm_sim_set_gravity(f.sim, misaligned(raw)));
    drop(&f);
  }
  ROW("set_gravity.nan", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(3);
    const double g[3][3] = {{NAN, 0.0, 0.0}, {0.0, NAN, 0.0}, {0.0, 0.0, NAN}};
    for (int k = 0; k < 3; ++k) {
      CALL(f.sim, rkmpm_sim_set_gravity(f.sim, g[k]));
    }
    drop(&f);
  }
  ROW("set_gravity.infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    const double g[2][2] = {{INFINITY, 0.0}, {0.0, -INFINITY}};
    for (int k = 0; k < 2; ++k) {
      CALL(f.sim, rkmpm_sim_set_gravity(f.sim, g[k]));
    }
    drop(&f);
  }

  /* ---- rkmpm_sim_set_boundary ---- */
  ROW("set_boundary.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_boundary(NULL, 0, -1, RKMPM_BOUNDARY_FIXED, 0.0));
  }
  ROW("set_boundary.unknown_kind", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_boundary(f.sim, 0, -1, 4, 0.0));
    CALL(f.sim, rkmpm_sim_set_boundary(f.sim, 0, 1, UINT32_MAX, 0.0));
    drop(&f);
  }
  ROW("set_boundary.bad_side", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    const int32_t sides[] = {0, 2, -2, INT32_MIN, INT32_MAX};
    for (size_t k = 0; k < sizeof sides / sizeof sides[0]; ++k) {
      CALL(f.sim, rkmpm_sim_set_boundary(f.sim, 0, sides[k], RKMPM_BOUNDARY_FIXED, 0.0));
    }
    drop(&f);
  }
  ROW("set_boundary.bad_axis", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_boundary(f.sim, 2, 1, RKMPM_BOUNDARY_FIXED, 0.0));
    CALL(f.sim, rkmpm_sim_set_boundary(f.sim, UINT32_MAX, 1, RKMPM_BOUNDARY_SLIP, 0.0));
    drop(&f);
    f = block(3);
    CALL(f.sim, rkmpm_sim_set_boundary(f.sim, 3, -1, RKMPM_BOUNDARY_FIXED, 0.0));
    drop(&f);
  }
  ROW("set_boundary.friction_negative", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_boundary(f.sim, 1, -1, RKMPM_BOUNDARY_FRICTION, -0.5));
    drop(&f);
  }
  ROW("set_boundary.friction_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_boundary(f.sim, 1, -1, RKMPM_BOUNDARY_FRICTION, NAN));
    drop(&f);
  }
  ROW("set_boundary.friction_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_boundary(f.sim, 1, 1, RKMPM_BOUNDARY_FRICTION, INFINITY));
    drop(&f);
  }

  /* ---- rkmpm_sim_set_body_force ---- */
  ROW("set_body_force.null_sim", RKMPM_ERR_NULL_POINTER) {
    ForceData data = {FORCE_COUNT, 0, 0.0, 0.0};
    CALL(NULL, rkmpm_sim_set_body_force(NULL, body_force, &data));
    EXPECT(data.calls == 0, "the callback was called");
  }
  ROW("set_body_force.null_function", RKMPM_OK) {
    Fixture f = block(2);
    ForceData data = {FORCE_COUNT, 0, 0.0, 0.0};
    RKMPM_CHECK(rkmpm_sim_set_body_force(f.sim, body_force, &data));
    take_step(&f);
    EXPECT(data.calls == 1, "the callback was called %d times in one step", data.calls);
    CALL(f.sim, rkmpm_sim_set_body_force(f.sim, NULL, &data));
    take_step(&f);
    EXPECT(data.calls == 1, "a removed callback was called");
    drop(&f);
  }

  /* ---- rkmpm_sim_set_progress ---- */
  ROW("set_progress.null_sim", RKMPM_ERR_NULL_POINTER) {
    ProgressData data = {0, 0, 0, 0.0, 0.0};
    CALL(NULL, rkmpm_sim_set_progress(NULL, progress, &data));
    EXPECT(data.calls == 0, "the callback was called");
  }
  ROW("set_progress.null_function", RKMPM_OK) {
    Fixture f = block(2);
    ProgressData data = {0, 0, 0, 0.0, 0.0};
    RKMPM_CHECK(rkmpm_sim_set_progress(f.sim, progress, &data));
    uint64_t n = 0;
    RKMPM_CHECK(rkmpm_sim_advance(f.sim, 3.0 * stable_dt(&f, 0.5), 0.5, &n));
    EXPECT(data.calls == (int)n && n >= 2, "%d progress calls for %llu steps", data.calls,
           (unsigned long long)n);
    double t = 0.0;
    RKMPM_CHECK(rkmpm_sim_time(f.sim, &t));
    EXPECT(data.time == t && data.end_time == t && data.steps == n,
           "the last report is not the end of the run");
    CALL(f.sim, rkmpm_sim_set_progress(f.sim, NULL, &data));
    RKMPM_CHECK(rkmpm_sim_advance(f.sim, stable_dt(&f, 0.5), 0.5, NULL));
    EXPECT(data.calls == (int)n, "a removed callback was called");
    drop(&f);
  }
}

static void material_rows(void) {
  _Alignas(8) unsigned char raw[256] = {0};

  /* ---- rkmpm_sim_add_material_linear_elastic ---- */
  ROW("add_material_linear_elastic.null_sim", RKMPM_ERR_NULL_POINTER) {
    uint32_t id = 77;
    CALL(NULL, rkmpm_sim_add_material_linear_elastic(NULL, 1.0, 100.0, 0.3, &id));
    EXPECT(id == 77, "wrote an id");
  }
  ROW("add_material_linear_elastic.null_out_id", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_material_linear_elastic(f.sim, 1.0, 100.0, 0.3, NULL));
    expect_material_rejected(&f, 77, __LINE__);
    drop(&f);
  }
  ROW("add_material_linear_elastic.misaligned_out_id", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_material_linear_elastic(f.sim, 1.0, 100.0, 0.3, misaligned(raw)));
    expect_material_rejected(&f, 77, __LINE__);
    drop(&f);
  }
  ROW("add_material_linear_elastic.density_not_positive", RKMPM_ERR_INVALID_ARGUMENT) {
    linear_elastic_rejects(0.0, 100.0, 0.3);
    linear_elastic_rejects(-1.0, 100.0, 0.3);
  }
  ROW("add_material_linear_elastic.density_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    linear_elastic_rejects(NAN, 100.0, 0.3);
  }
  ROW("add_material_linear_elastic.density_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    linear_elastic_rejects(INFINITY, 100.0, 0.3);
  }
  ROW("add_material_linear_elastic.young_not_positive", RKMPM_ERR_INVALID_ARGUMENT) {
    linear_elastic_rejects(1.0, 0.0, 0.3);
    linear_elastic_rejects(1.0, -100.0, 0.3);
  }
  ROW("add_material_linear_elastic.young_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    linear_elastic_rejects(1.0, NAN, 0.3);
  }
  ROW("add_material_linear_elastic.young_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    linear_elastic_rejects(1.0, INFINITY, 0.3);
  }
  ROW("add_material_linear_elastic.poisson_out_of_range", RKMPM_ERR_INVALID_ARGUMENT) {
    linear_elastic_rejects(1.0, 100.0, 0.5);
    linear_elastic_rejects(1.0, 100.0, -1.0);
    linear_elastic_rejects(1.0, 100.0, 2.0);
  }
  ROW("add_material_linear_elastic.poisson_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    linear_elastic_rejects(1.0, 100.0, NAN);
  }
  ROW("add_material_linear_elastic.derived_overflow", RKMPM_ERR_INVALID_ARGUMENT) {
    linear_elastic_rejects(1.0, 1e308, 0.49);  /* lambda overflows */
    linear_elastic_rejects(1e-300, 1e300, 0.3); /* the wave speed overflows */
  }
  ROW("add_material_linear_elastic.faster_than_any_solid", RKMPM_ERR_INVALID_ARGUMENT) {
    linear_elastic_rejects(1000.0, 1e300, 0.3); /* 3.7e148 m/s */
    linear_elastic_rejects(1.0, 1e10, 0.3);     /* 1.2e5 m/s */
  }
  ROW("add_material_linear_elastic.density_below_bound", RKMPM_ERR_INVALID_ARGUMENT) {
    linear_elastic_rejects(1e-300, 1e-300, 0.3);
  }

  /* ---- rkmpm_sim_add_material_neo_hookean ---- */
  ROW("add_material_neo_hookean.null_sim", RKMPM_ERR_NULL_POINTER) {
    uint32_t id = 77;
    CALL(NULL, rkmpm_sim_add_material_neo_hookean(NULL, 1.0, 100.0, 0.3, &id));
    EXPECT(id == 77, "wrote an id");
  }
  ROW("add_material_neo_hookean.null_out_id", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_material_neo_hookean(f.sim, 1.0, 100.0, 0.3, NULL));
    expect_material_rejected(&f, 77, __LINE__);
    drop(&f);
  }
  ROW("add_material_neo_hookean.misaligned_out_id", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_material_neo_hookean(f.sim, 1.0, 100.0, 0.3, misaligned(raw)));
    expect_material_rejected(&f, 77, __LINE__);
    drop(&f);
  }
  ROW("add_material_neo_hookean.density_not_positive", RKMPM_ERR_INVALID_ARGUMENT) {
    neo_hookean_rejects(0.0, 100.0, 0.3);
    neo_hookean_rejects(-1.0, 100.0, 0.3);
  }
  ROW("add_material_neo_hookean.density_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    neo_hookean_rejects(NAN, 100.0, 0.3);
  }
  ROW("add_material_neo_hookean.density_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    neo_hookean_rejects(INFINITY, 100.0, 0.3);
  }
  ROW("add_material_neo_hookean.young_not_positive", RKMPM_ERR_INVALID_ARGUMENT) {
    neo_hookean_rejects(1.0, 0.0, 0.3);
    neo_hookean_rejects(1.0, -100.0, 0.3);
  }
  ROW("add_material_neo_hookean.young_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    neo_hookean_rejects(1.0, NAN, 0.3);
  }
  ROW("add_material_neo_hookean.young_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    neo_hookean_rejects(1.0, INFINITY, 0.3);
  }
  ROW("add_material_neo_hookean.poisson_out_of_range", RKMPM_ERR_INVALID_ARGUMENT) {
    neo_hookean_rejects(1.0, 100.0, 0.5);
    neo_hookean_rejects(1.0, 100.0, -1.0);
  }
  ROW("add_material_neo_hookean.poisson_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    neo_hookean_rejects(1.0, 100.0, NAN);
  }
  ROW("add_material_neo_hookean.derived_overflow", RKMPM_ERR_INVALID_ARGUMENT) {
    neo_hookean_rejects(1.0, 1e308, 0.49);
    neo_hookean_rejects(1e-300, 1e300, 0.3);
  }
  ROW("add_material_neo_hookean.faster_than_any_solid", RKMPM_ERR_INVALID_ARGUMENT) {
    neo_hookean_rejects(1000.0, 1e300, 0.3);
    neo_hookean_rejects(1.0, 1e10, 0.3);
  }
  ROW("add_material_neo_hookean.density_below_bound", RKMPM_ERR_INVALID_ARGUMENT) {
    neo_hookean_rejects(1e-300, 1e-300, 0.3);
  }

  /* ---- rkmpm_sim_add_material_drucker_prager ---- */
  ROW("add_material_drucker_prager.null_sim", RKMPM_ERR_NULL_POINTER) {
    uint32_t id = 77;
    CALL(NULL, rkmpm_sim_add_material_drucker_prager(NULL, 2650.0, 1e6, 0.3, 30.0, 0.0, 0.0, &id));
    EXPECT(id == 77, "wrote an id");
  }
  ROW("add_material_drucker_prager.null_out_id", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_material_drucker_prager(f.sim, 2650.0, 1e6, 0.3, 30.0, 0.0, 0.0,
                                                      NULL));
    expect_material_rejected(&f, 77, __LINE__);
    drop(&f);
  }
  ROW("add_material_drucker_prager.misaligned_out_id", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_material_drucker_prager(f.sim, 2650.0, 1e6, 0.3, 30.0, 0.0, 0.0,
                                                      misaligned(raw)));
    expect_material_rejected(&f, 77, __LINE__);
    drop(&f);
  }
  ROW("add_material_drucker_prager.elastic_invalid", RKMPM_ERR_INVALID_ARGUMENT) {
    drucker_prager_rejects(NAN, 1e6, 0.3, 30.0, 0.0, 0.0);
    drucker_prager_rejects(2650.0, 0.0, 0.3, 30.0, 0.0, 0.0);
    drucker_prager_rejects(2650.0, 1e6, 0.5, 30.0, 0.0, 0.0);
  }
  ROW("add_material_drucker_prager.friction_angle_out_of_range", RKMPM_ERR_INVALID_ARGUMENT) {
    drucker_prager_rejects(2650.0, 1e6, 0.3, 90.0, 0.0, 0.0);
    drucker_prager_rejects(2650.0, 1e6, 0.3, -1.0, 100.0, 0.0);
  }
  ROW("add_material_drucker_prager.friction_angle_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    drucker_prager_rejects(2650.0, 1e6, 0.3, NAN, 100.0, 0.0);
    drucker_prager_rejects(2650.0, 1e6, 0.3, INFINITY, 100.0, 0.0);
  }
  ROW("add_material_drucker_prager.cohesion_negative", RKMPM_ERR_INVALID_ARGUMENT) {
    drucker_prager_rejects(2650.0, 1e6, 0.3, 30.0, -1.0, 0.0);
  }
  ROW("add_material_drucker_prager.cohesion_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    drucker_prager_rejects(2650.0, 1e6, 0.3, 30.0, NAN, 0.0);
    drucker_prager_rejects(2650.0, 1e6, 0.3, 30.0, INFINITY, 0.0);
  }
  ROW("add_material_drucker_prager.dilatancy_out_of_range", RKMPM_ERR_INVALID_ARGUMENT) {
    drucker_prager_rejects(2650.0, 1e6, 0.3, 30.0, 0.0, 31.0);
    drucker_prager_rejects(2650.0, 1e6, 0.3, 30.0, 0.0, -1.0);
  }
  ROW("add_material_drucker_prager.dilatancy_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    drucker_prager_rejects(2650.0, 1e6, 0.3, 30.0, 0.0, NAN);
    drucker_prager_rejects(2650.0, 1e6, 0.3, 30.0, 0.0, -INFINITY);
  }
  ROW("add_material_drucker_prager.no_strength", RKMPM_ERR_INVALID_ARGUMENT) {
    drucker_prager_rejects(2650.0, 1e6, 0.3, 0.0, 0.0, 0.0);
  }
  ROW("add_material_drucker_prager.derived_overflow", RKMPM_ERR_INVALID_ARGUMENT) {
    drucker_prager_rejects(1.0, 1e308, 0.49, 30.0, 0.0, 0.0);
  }
  ROW("add_material_drucker_prager.faster_than_any_solid", RKMPM_ERR_INVALID_ARGUMENT) {
    drucker_prager_rejects(2650.0, 1e300, 0.3, 30.0, 0.0, 0.0);
  }

  /* ---- rkmpm_sim_set_drucker_prager_rheology ---- */
  ROW("set_drucker_prager_rheology.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_drucker_prager_rheology(NULL, 0, 1, 0.26, 0.28, 1e-3));
  }
  ROW("set_drucker_prager_rheology.bad_flag", RKMPM_ERR_INVALID_ARGUMENT) {
    rheology_rejects(2, 0.26, 0.28, 1e-3);
    rheology_rejects(UINT32_MAX, 0.26, 0.28, 1e-3);
  }
  ROW("set_drucker_prager_rheology.friction_increase_invalid", RKMPM_ERR_INVALID_ARGUMENT) {
    rheology_rejects(1, -0.1, 0.28, 1e-3);
    rheology_rejects(1, NAN, 0.28, 1e-3);
    rheology_rejects(1, INFINITY, 0.28, 1e-3);
  }
  ROW("set_drucker_prager_rheology.inertial_number_invalid", RKMPM_ERR_INVALID_ARGUMENT) {
    rheology_rejects(1, 0.26, 0.0, 1e-3);
    rheology_rejects(1, 0.26, -1.0, 1e-3);
    rheology_rejects(1, 0.26, NAN, 1e-3);
  }
  ROW("set_drucker_prager_rheology.grain_diameter_invalid", RKMPM_ERR_INVALID_ARGUMENT) {
    rheology_rejects(1, 0.26, 0.28, 0.0);
    rheology_rejects(1, 0.26, 0.28, -1e-3);
    rheology_rejects(1, 0.26, 0.28, INFINITY);
  }
  ROW("set_drucker_prager_rheology.unknown_material", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_drucker_prager_rheology(f.sim, 1, 1, 0.26, 0.28, 1e-3));
    CALL(f.sim, rkmpm_sim_set_drucker_prager_rheology(f.sim, UINT32_MAX, 0, 0.0, 0.0, 0.0));
    drop(&f);
  }
  ROW("set_drucker_prager_rheology.not_drucker_prager", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2); /* material 0 is elastic */
    CALL(f.sim, rkmpm_sim_set_drucker_prager_rheology(f.sim, 0, 1, 0.26, 0.28, 1e-3));
    CALL(f.sim, rkmpm_sim_set_drucker_prager_rheology(f.sim, 0, 0, 0.0, 0.0, 0.0));
    drop(&f);
  }

  /* ---- rkmpm_sim_add_material_johnson_cook ---- */
  ROW("add_material_johnson_cook.null_sim", RKMPM_ERR_NULL_POINTER) {
    RkmpmJohnsonCook p = copper();
    uint32_t id = 77;
    CALL(NULL, rkmpm_sim_add_material_johnson_cook(NULL, &p, &id));
    EXPECT(id == 77, "wrote an id");
  }
  ROW("add_material_johnson_cook.null_parameters", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    uint32_t id = 77;
    CALL(f.sim, rkmpm_sim_add_material_johnson_cook(f.sim, NULL, &id));
    expect_material_rejected(&f, id, __LINE__);
    drop(&f);
  }
  ROW("add_material_johnson_cook.null_out_id", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    RkmpmJohnsonCook p = copper();
    CALL(f.sim, rkmpm_sim_add_material_johnson_cook(f.sim, &p, NULL));
    expect_material_rejected(&f, 77, __LINE__);
    drop(&f);
  }
  ROW("add_material_johnson_cook.misaligned_parameters", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    RkmpmJohnsonCook p = copper();
    memcpy(raw + 1, &p, sizeof p);
    uint32_t id = 77;
    CALL(f.sim, rkmpm_sim_add_material_johnson_cook(f.sim, misaligned(raw), &id));
    expect_material_rejected(&f, id, __LINE__);
    drop(&f);
    memset(raw, 0, sizeof raw);
  }
  ROW("add_material_johnson_cook.misaligned_out_id", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    RkmpmJohnsonCook p = copper();
    CALL(f.sim, rkmpm_sim_add_material_johnson_cook(f.sim, &p, misaligned(raw)));
    expect_material_rejected(&f, 77, __LINE__);
    drop(&f);
  }
  ROW("add_material_johnson_cook.damage_flag", RKMPM_ERR_INVALID_ARGUMENT) {
    RkmpmJohnsonCook p = copper();
    p.damage_enabled = 2;
    johnson_cook_rejects(p);
    p.damage_enabled = UINT32_MAX;
    johnson_cook_rejects(p);
  }
  ROW("add_material_johnson_cook.eos_flag", RKMPM_ERR_INVALID_ARGUMENT) {
    RkmpmJohnsonCook p = copper();
    p.eos_enabled = 7;
    johnson_cook_rejects(p);
  }
  ROW("add_material_johnson_cook.elastic_invalid", RKMPM_ERR_INVALID_ARGUMENT) {
    RkmpmJohnsonCook p = copper();
    p.density = 0.0;
    johnson_cook_rejects(p);
    p = copper();
    p.young = NAN;
    johnson_cook_rejects(p);
    p = copper();
    p.poisson = 0.5;
    johnson_cook_rejects(p);
  }
  ROW("add_material_johnson_cook.a_not_positive", RKMPM_ERR_INVALID_ARGUMENT) {
    RkmpmJohnsonCook p = copper();
    p.a = 0.0;
    johnson_cook_rejects(p);
    p.a = NAN;
    johnson_cook_rejects(p);
    p.a = INFINITY;
    johnson_cook_rejects(p);
  }
  ROW("add_material_johnson_cook.hardening_negative", RKMPM_ERR_INVALID_ARGUMENT) {
    for (int k = 0; k < 4; ++k) {
      RkmpmJohnsonCook p = copper();
      double *v[4] = {&p.b, &p.n, &p.c, &p.m};
      *v[k] = -0.1;
      johnson_cook_rejects(p);
    }
  }
  ROW("add_material_johnson_cook.hardening_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    for (int k = 0; k < 4; ++k) {
      RkmpmJohnsonCook p = copper();
      double *v[4] = {&p.b, &p.n, &p.c, &p.m};
      *v[k] = k % 2 == 0 ? NAN : INFINITY;
      johnson_cook_rejects(p);
    }
  }
  ROW("add_material_johnson_cook.reference_strain_rate_not_positive", RKMPM_ERR_INVALID_ARGUMENT) {
    RkmpmJohnsonCook p = copper();
    p.reference_strain_rate = 0.0;
    johnson_cook_rejects(p);
    p.reference_strain_rate = NAN;
    johnson_cook_rejects(p);
  }
  ROW("add_material_johnson_cook.specific_heat_not_positive", RKMPM_ERR_INVALID_ARGUMENT) {
    RkmpmJohnsonCook p = copper();
    p.specific_heat = -383.0;
    johnson_cook_rejects(p);
    p.specific_heat = INFINITY;
    johnson_cook_rejects(p);
  }
  ROW("add_material_johnson_cook.room_temperature_not_positive", RKMPM_ERR_INVALID_ARGUMENT) {
    RkmpmJohnsonCook p = copper();
    p.room_temperature = 0.0;
    johnson_cook_rejects(p);
    p.room_temperature = NAN;
    johnson_cook_rejects(p);
  }
  ROW("add_material_johnson_cook.melt_not_above_room", RKMPM_ERR_INVALID_ARGUMENT) {
    RkmpmJohnsonCook p = copper();
    p.melt_temperature = 298.0;
    johnson_cook_rejects(p);
    p.melt_temperature = 200.0;
    johnson_cook_rejects(p);
    p.melt_temperature = NAN;
    johnson_cook_rejects(p);
    p.melt_temperature = INFINITY;
    johnson_cook_rejects(p);
  }
  ROW("add_material_johnson_cook.taylor_quinney_out_of_range", RKMPM_ERR_INVALID_ARGUMENT) {
    RkmpmJohnsonCook p = copper();
    p.taylor_quinney = 1.5;
    johnson_cook_rejects(p);
    p.taylor_quinney = -0.1;
    johnson_cook_rejects(p);
    p.taylor_quinney = NAN;
    johnson_cook_rejects(p);
  }
  ROW("add_material_johnson_cook.damage_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    RkmpmJohnsonCook p = copper();
    p.d3 = NAN;
    johnson_cook_rejects(p);
    p = copper();
    p.d5 = -INFINITY;
    johnson_cook_rejects(p);
  }
  ROW("add_material_johnson_cook.eos_invalid", RKMPM_ERR_INVALID_ARGUMENT) {
    RkmpmJohnsonCook p = copper();
    p.eos_sound_speed = 0.0;
    johnson_cook_rejects(p);
    p = copper();
    p.eos_slope = 0.9;
    johnson_cook_rejects(p);
    p = copper();
    p.eos_gamma0 = -0.1;
    johnson_cook_rejects(p);
    p = copper();
    p.eos_slope = NAN;
    johnson_cook_rejects(p);
    p = copper();
    p.eos_gamma0 = INFINITY;
    johnson_cook_rejects(p);
  }
  ROW("add_material_johnson_cook.derived_overflow", RKMPM_ERR_INVALID_ARGUMENT) {
    RkmpmJohnsonCook p = copper();
    p.eos_enabled = 0;
    p.young = 1e308;
    p.poisson = 0.49;
    johnson_cook_rejects(p);
  }

  /* ---- rkmpm_sim_add_material_rigid ---- */
  const double still[3] = {0.0, 0.0, 0.0};
  ROW("add_material_rigid.null_sim", RKMPM_ERR_NULL_POINTER) {
    uint32_t id = 77;
    CALL(NULL, rkmpm_sim_add_material_rigid(NULL, 1.0, still, &id));
    EXPECT(id == 77, "wrote an id");
  }
  ROW("add_material_rigid.null_out_id", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_material_rigid(f.sim, 1.0, still, NULL));
    expect_material_rejected(&f, 77, __LINE__);
    drop(&f);
  }
  ROW("add_material_rigid.null_velocity", RKMPM_ERR_NULL_POINTER) {
    rigid_rejects(2, 1.0, NULL);
    rigid_rejects(3, 1.0, NULL);
  }
  ROW("add_material_rigid.misaligned_velocity", RKMPM_ERR_INVALID_ARGUMENT) {
    rigid_rejects(2, 1.0, misaligned(raw));
  }
  ROW("add_material_rigid.misaligned_out_id", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_material_rigid(f.sim, 1.0, still, misaligned(raw)));
    expect_material_rejected(&f, 77, __LINE__);
    drop(&f);
  }
  ROW("add_material_rigid.density_not_positive", RKMPM_ERR_INVALID_ARGUMENT) {
    rigid_rejects(2, 0.0, still);
    rigid_rejects(2, -1.0, still);
  }
  ROW("add_material_rigid.density_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    rigid_rejects(2, NAN, still);
  }
  ROW("add_material_rigid.density_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    rigid_rejects(3, INFINITY, still);
  }
  ROW("add_material_rigid.density_below_bound", RKMPM_ERR_INVALID_ARGUMENT) {
    const double still[3] = {0.0, 0.0, 0.0};
    rigid_rejects(2, 1e-300, still);
  }
  ROW("add_material_rigid.velocity_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    const double v2[2] = {0.0, NAN}, v3[3] = {0.0, 0.0, NAN};
    rigid_rejects(2, 1.0, v2);
    rigid_rejects(3, 1.0, v3);
  }
  ROW("add_material_rigid.velocity_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    const double v[2] = {-INFINITY, 0.0};
    rigid_rejects(2, 1.0, v);
  }

  /* ---- rkmpm_sim_set_rigid_velocity ---- */
  ROW("set_rigid_velocity.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_rigid_velocity(NULL, 1, still));
  }
  ROW("set_rigid_velocity.null_velocity", RKMPM_ERR_NULL_POINTER) {
    rigid_velocity_rejects(2, 1, NULL);
    rigid_velocity_rejects(3, 1, NULL);
  }
  ROW("set_rigid_velocity.misaligned_velocity", RKMPM_ERR_INVALID_ARGUMENT) {
    rigid_velocity_rejects(2, 1, misaligned(raw));
  }
  ROW("set_rigid_velocity.velocity_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    const double v2[2] = {0.0, NAN}, v3[3] = {0.0, 0.0, NAN};
    rigid_velocity_rejects(2, 1, v2);
    rigid_velocity_rejects(3, 1, v3);
  }
  ROW("set_rigid_velocity.velocity_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    const double v[2] = {INFINITY, 0.0};
    rigid_velocity_rejects(2, 1, v);
  }
  ROW("set_rigid_velocity.unknown_material", RKMPM_ERR_UNKNOWN_MATERIAL) {
    rigid_velocity_rejects(2, 2, still);
    rigid_velocity_rejects(2, UINT32_MAX, still);
  }
  ROW("set_rigid_velocity.not_rigid", RKMPM_ERR_INVALID_ARGUMENT) {
    rigid_velocity_rejects(2, 0, still); /* material 0 is elastic */
  }
}

static void particle_rows(void) {
  _Alignas(8) unsigned char raw[256] = {0};
  const double x2[4] = {0.5, 0.5, 0.55, 0.55}, vol2[2] = {1e-3, 1e-3}, v2[4] = {0.1, 0.0, 0.0, 0.1};

  /* ---- rkmpm_sim_add_particles ---- */
  ROW("add_particles.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_add_particles(NULL, 0, 2, x2, vol2, NULL));
  }
  ROW("add_particles.null_positions", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_particles(f.sim, f.material, 2, NULL, vol2, v2));
    drop(&f);
  }
  ROW("add_particles.null_volumes", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_particles(f.sim, f.material, 2, x2, NULL, NULL));
    drop(&f);
  }
  ROW("add_particles.misaligned_positions", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_particles(f.sim, f.material, 2, misaligned(raw), vol2, NULL));
    drop(&f);
  }
  ROW("add_particles.misaligned_volumes", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_particles(f.sim, f.material, 2, x2, misaligned(raw), NULL));
    drop(&f);
  }
  ROW("add_particles.misaligned_velocities", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_particles(f.sim, f.material, 2, x2, vol2, misaligned(raw)));
    drop(&f);
  }
  ROW("add_particles.zero_count", RKMPM_OK) {
    for (uint32_t dim = 2; dim <= 3; ++dim) {
      Fixture f = block(dim);
      CALL(f.sim, rkmpm_sim_add_particles(f.sim, f.material, 0, NULL, NULL, NULL));
      CALL(f.sim, rkmpm_sim_add_particles(f.sim, f.material, 0, x2, vol2, v2));
      drop(&f);
    }
  }
  ROW("add_particles.huge_count", RKMPM_ERR_INVALID_ARGUMENT) {
    for (uint32_t dim = 2; dim <= 3; ++dim) {
      Fixture f = block(dim);
      CALL(f.sim, rkmpm_sim_add_particles(f.sim, f.material, SIZE_MAX, x2, vol2, NULL));
      CALL(f.sim, rkmpm_sim_add_particles(f.sim, f.material, SIZE_MAX / dim + 1, x2, vol2, v2));
      drop(&f);
    }
  }
  ROW("add_particles.too_many", RKMPM_ERR_INVALID_ARGUMENT) {
    for (uint32_t dim = 2; dim <= 3; ++dim) {
      Fixture f = block(dim);
      CALL(f.sim, rkmpm_sim_add_particles(f.sim, f.material, SIZE_MAX / dim, x2, vol2, NULL));
      CALL(f.sim, rkmpm_sim_add_particles(f.sim, f.material, (SIZE_MAX / 16) / dim + 1, x2,
                                          vol2, NULL));
      drop(&f);
    }
  }
  ROW("add_particles.unknown_material", RKMPM_ERR_UNKNOWN_MATERIAL) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_particles(f.sim, 1, 2, x2, vol2, NULL));
    CALL(f.sim, rkmpm_sim_add_particles(f.sim, UINT32_MAX, 2, x2, vol2, NULL));
    drop(&f);
    f = empty_sim(3);
    const double x3[3] = {0.5, 0.5, 0.5};
    CALL(f.sim, rkmpm_sim_add_particles(f.sim, 0, 1, x3, vol2, NULL));
    drop(&f);
  }
  ROW("add_particles.unknown_material_zero_count", RKMPM_ERR_UNKNOWN_MATERIAL) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_particles(f.sim, 5, 0, NULL, NULL, NULL));
    drop(&f);
  }
  ROW("add_particles.position_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    const double x[4] = {0.5, 0.5, 0.5, NAN};
    particles_reject(x, vol2, NULL);
  }
  ROW("add_particles.position_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    const double x[4] = {0.5, 0.5, INFINITY, 0.5};
    particles_reject(x, vol2, NULL);
  }
  ROW("add_particles.outside_grid", RKMPM_ERR_OUTSIDE_GRID) {
    const double x[4][4] = {{0.5, 0.5, 1.5, 0.5},
                            {0.5, 0.5, 0.5, -1e-9},
                            {0.5, 0.5, -0.5, 0.5},
                            {0.5, 0.5, 0.5, 1.0 + 1e-9}};
    for (int k = 0; k < 4; ++k) {
      particles_reject(x[k], vol2, NULL);
    }
    Fixture f = block(3);
    const double x3[6] = {0.5, 0.5, 0.5, 0.5, 0.5, 1.01}, vol3[2] = {1e-4, 1e-4};
    CALL(f.sim, rkmpm_sim_add_particles(f.sim, f.material, 2, x3, vol3, NULL));
    drop(&f);
  }
  ROW("add_particles.volume_not_positive", RKMPM_ERR_INVALID_ARGUMENT) {
    const double zero[2] = {1e-3, 0.0}, negative[2] = {1e-3, -1e-3};
    particles_reject(x2, zero, NULL);
    particles_reject(x2, negative, NULL);
  }
  ROW("add_particles.volume_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    const double vol[2] = {1e-3, NAN};
    particles_reject(x2, vol, NULL);
  }
  ROW("add_particles.volume_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    const double vol[2] = {1e-3, INFINITY};
    particles_reject(x2, vol, NULL);
  }
  ROW("add_particles.volume_exceeds_domain", RKMPM_ERR_INVALID_ARGUMENT) {
    const double vol[2] = {1e-3, 1.5}; /* the domain is 1 x 1 */
    particles_reject(x2, vol, NULL);
  }
  ROW("add_particles.velocity_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    const double v[4] = {0.0, 0.0, NAN, 0.0};
    particles_reject(x2, vol2, v);
  }
  ROW("add_particles.velocity_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    const double v[4] = {0.0, 0.0, 0.0, -INFINITY};
    particles_reject(x2, vol2, v);
  }
  ROW("add_particles.mass_overflow", RKMPM_ERR_INVALID_ARGUMENT) {
    /* density 1e300 and a particle of 1e10 m^2 in a 1e5 x 1e5 domain: mass 1e310 = inf. */
    const size_t cells[2] = {100, 100};
    RkmpmSim *sim = NULL;
    RKMPM_CHECK(rkmpm_sim_new(2, ORIGIN, cells, 1e3, &sim));
    uint32_t heavy = 0;
    RKMPM_CHECK(rkmpm_sim_add_material_linear_elastic(sim, 1e300, 1e300, 0.3, &heavy));
    const double x[2] = {5e4, 5e4}, vol[1] = {1e10};
    CALL(sim, rkmpm_sim_add_particles(sim, heavy, 1, x, vol, NULL));
    rkmpm_sim_free(sim);
  }

  /* ---- rkmpm_sim_add_boundary_points ---- */
  const double bx[4] = {0.4, 0.45, 0.4, 0.5}, bn[4] = {-0.05, 0.0, -0.05, 0.0};
  const double bt[4] = {0.0, 0.0, 1.0, 0.0};
  ROW("add_boundary_points.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_add_boundary_points(NULL, 2, bx, bn, NULL));
  }
  ROW("add_boundary_points.null_positions", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_boundary_points(f.sim, 2, NULL, bn, bt));
    drop(&f);
  }
  ROW("add_boundary_points.null_area_normals", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_boundary_points(f.sim, 2, bx, NULL, NULL));
    drop(&f);
  }
  ROW("add_boundary_points.misaligned_positions", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_boundary_points(f.sim, 2, misaligned(raw), bn, NULL));
    drop(&f);
  }
  ROW("add_boundary_points.misaligned_area_normals", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_boundary_points(f.sim, 2, bx, misaligned(raw), NULL));
    drop(&f);
  }
  ROW("add_boundary_points.misaligned_tractions", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_add_boundary_points(f.sim, 2, bx, bn, misaligned(raw)));
    drop(&f);
  }
  ROW("add_boundary_points.zero_count", RKMPM_OK) {
    Fixture f = block(3);
    CALL(f.sim, rkmpm_sim_add_boundary_points(f.sim, 0, NULL, NULL, NULL));
    drop(&f);
  }
  ROW("add_boundary_points.huge_count", RKMPM_ERR_INVALID_ARGUMENT) {
    for (uint32_t dim = 2; dim <= 3; ++dim) {
      Fixture f = block(dim);
      CALL(f.sim, rkmpm_sim_add_boundary_points(f.sim, SIZE_MAX, bx, bn, NULL));
      CALL(f.sim, rkmpm_sim_add_boundary_points(f.sim, SIZE_MAX / dim + 1, bx, bn, bt));
      drop(&f);
    }
  }
  ROW("add_boundary_points.too_many", RKMPM_ERR_INVALID_ARGUMENT) {
    for (uint32_t dim = 2; dim <= 3; ++dim) {
      Fixture f = block(dim);
      CALL(f.sim, rkmpm_sim_add_boundary_points(f.sim, SIZE_MAX / dim, bx, bn, NULL));
      drop(&f);
    }
  }
  ROW("add_boundary_points.position_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    const double x[4] = {0.4, 0.45, 0.4, NAN};
    boundary_points_reject(x, bn, NULL);
  }
  ROW("add_boundary_points.position_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    const double x[4] = {0.4, 0.45, INFINITY, 0.5};
    boundary_points_reject(x, bn, NULL);
  }
  ROW("add_boundary_points.outside_grid", RKMPM_ERR_OUTSIDE_GRID) {
    const double x[4] = {0.4, 0.45, 0.4, 1.6};
    boundary_points_reject(x, bn, bt);
  }
  ROW("add_boundary_points.area_normal_zero", RKMPM_ERR_INVALID_ARGUMENT) {
    const double n[4] = {-0.05, 0.0, 0.0, 0.0};
    boundary_points_reject(bx, n, NULL);
  }
  ROW("add_boundary_points.area_normal_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    const double n[4] = {-0.05, 0.0, NAN, 0.0};
    boundary_points_reject(bx, n, NULL);
  }
  ROW("add_boundary_points.area_normal_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    const double n[4] = {-0.05, 0.0, -INFINITY, 0.0};
    boundary_points_reject(bx, n, NULL);
  }
  ROW("add_boundary_points.traction_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    const double t[4] = {0.0, 0.0, 0.0, NAN};
    boundary_points_reject(bx, bn, t);
  }
  ROW("add_boundary_points.traction_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    const double t[4] = {0.0, 0.0, INFINITY, 0.0};
    boundary_points_reject(bx, bn, t);
  }
}

static void step_rows(void) {
  _Alignas(8) unsigned char raw[64] = {0};

  /* ---- rkmpm_sim_stable_dt ---- */
  ROW("stable_dt.null_sim", RKMPM_ERR_NULL_POINTER) {
    double dt = 77.0;
    CALL(NULL, rkmpm_sim_stable_dt(NULL, 0.5, &dt));
    EXPECT(dt == 77.0, "wrote the output after a failure");
  }
  ROW("stable_dt.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_stable_dt(f.sim, 0.5, NULL));
    drop(&f);
  }
  ROW("stable_dt.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_stable_dt(f.sim, 0.5, misaligned(raw)));
    drop(&f);
  }
  ROW("stable_dt.cfl_not_positive", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    double dt = 77.0;
    CALL(f.sim, rkmpm_sim_stable_dt(f.sim, 0.0, &dt));
    CALL(f.sim, rkmpm_sim_stable_dt(f.sim, -0.0, &dt));
    CALL(f.sim, rkmpm_sim_stable_dt(f.sim, -0.5, &dt));
    EXPECT(dt == 77.0, "wrote the output after a failure");
    drop(&f);
  }
  ROW("stable_dt.cfl_above_one", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    double dt = 77.0;
    CALL(f.sim, rkmpm_sim_stable_dt(f.sim, 1.0000001, &dt));
    CALL(f.sim, rkmpm_sim_stable_dt(f.sim, 2.0, &dt));
    EXPECT(dt == 77.0, "wrote the output after a failure");
    drop(&f);
  }
  ROW("stable_dt.cfl_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    double dt = 77.0;
    CALL(f.sim, rkmpm_sim_stable_dt(f.sim, NAN, &dt));
    drop(&f);
  }
  ROW("stable_dt.cfl_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    double dt = 77.0;
    CALL(f.sim, rkmpm_sim_stable_dt(f.sim, INFINITY, &dt));
    drop(&f);
  }
  ROW("stable_dt.no_particles", RKMPM_ERR_INVALID_STATE) {
    Fixture f = empty_sim(3);
    RKMPM_CHECK(rkmpm_sim_add_material_linear_elastic(f.sim, 1.0, 100.0, 0.3, &f.material));
    double dt = 77.0;
    CALL(f.sim, rkmpm_sim_stable_dt(f.sim, 0.5, &dt));
    EXPECT(dt == 77.0, "wrote the output after a failure");
    drop(&f);
  }
  ROW("stable_dt.zero_wave_speed", RKMPM_ERR_INVALID_STATE) {
    /* Only a rigid body at rest: no wave speed and no velocity, so no time scale. */
    Fixture f = empty_sim(2);
    const double still[2] = {0.0, 0.0}, x[2] = {0.5, 0.5}, vol[1] = {1e-3};
    RKMPM_CHECK(rkmpm_sim_add_material_rigid(f.sim, 1.0, still, &f.material));
    RKMPM_CHECK(rkmpm_sim_add_particles(f.sim, f.material, 1, x, vol, NULL));
    double dt = 77.0;
    CALL(f.sim, rkmpm_sim_stable_dt(f.sim, 0.5, &dt));
    EXPECT(dt == 77.0, "wrote %g to *out_dt", dt);
    drop(&f);
  }

  /* ---- rkmpm_sim_step ---- */
  ROW("step.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_step(NULL, 1e-3));
  }
  ROW("step.misaligned_sim", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_step(misaligned(f.sim), stable_dt(&f, 0.5)));
    drop(&f);
  }
  ROW("step.dt_not_positive", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_step(f.sim, 0.0));
    CALL(f.sim, rkmpm_sim_step(f.sim, -0.0));
    CALL(f.sim, rkmpm_sim_step(f.sim, -1e-4));
    drop(&f);
    f = empty_sim(2); /* also without particles */
    CALL(f.sim, rkmpm_sim_step(f.sim, -1.0));
    drop(&f);
  }
  ROW("step.dt_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_step(f.sim, NAN));
    drop(&f);
    f = empty_sim(3);
    CALL(f.sim, rkmpm_sim_step(f.sim, NAN));
    drop(&f);
  }
  ROW("step.dt_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_step(f.sim, INFINITY));
    drop(&f);
    f = empty_sim(2);
    CALL(f.sim, rkmpm_sim_step(f.sim, INFINITY));
    drop(&f);
  }
  ROW("step.dt_above_critical", RKMPM_ERR_UNSTABLE_TIME_STEP) {
    Fixture f = stepped_block(2);
    const double critical = stable_dt(&f, 1.0);
    CALL(f.sim, rkmpm_sim_step(f.sim, 1.01 * critical));
    CALL(f.sim, rkmpm_sim_step(f.sim, DBL_MAX));
    drop(&f);
  }
  ROW("step.no_particles", RKMPM_OK) {
    Fixture f = empty_sim(2);
    CALL(NULL, rkmpm_sim_step(f.sim, 1e-3)); /* changes the time and the step count only */
    double t = 0.0;
    uint64_t steps = 0;
    RKMPM_CHECK(rkmpm_sim_time(f.sim, &t));
    RKMPM_CHECK(rkmpm_sim_step_count(f.sim, &steps));
    EXPECT(t == 1e-3 && steps == 1, "time %g, steps %llu after one step", t,
           (unsigned long long)steps);
    EXPECT(rkmpm_sim_particle_count(f.sim) == 0, "particles appeared");
    drop(&f);
  }
  ROW("step.time_overflow", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = empty_sim(2);
    RKMPM_CHECK(rkmpm_sim_step(f.sim, DBL_MAX));
    CALL(f.sim, rkmpm_sim_step(f.sim, DBL_MAX)); /* the time would become +inf */
    drop(&f);
  }
  ROW("step.callback_error", RKMPM_ERR_CALLBACK) {
    Fixture f = block(2);
    ForceData data = {FORCE_RETURN_ERROR, 0, 0.0, 0.0};
    RKMPM_CHECK(rkmpm_sim_set_body_force(f.sim, body_force, &data));
    CALL(f.sim, rkmpm_sim_step(f.sim, stable_dt(&f, 0.5)));
    EXPECT(data.calls == 1, "the callback was called %d times", data.calls);
    drop(&f);
  }
  ROW("step.callback_nan", RKMPM_ERR_CALLBACK) {
    Fixture f = stepped_block(3);
    ForceData data = {FORCE_WRITE_NAN, 0, 0.0, 0.0};
    RKMPM_CHECK(rkmpm_sim_set_body_force(f.sim, body_force, &data));
    CALL(f.sim, rkmpm_sim_step(f.sim, stable_dt(&f, 0.5)));
    drop(&f);
  }
  ROW("step.callback_infinite", RKMPM_ERR_CALLBACK) {
    Fixture f = block(2);
    ForceData data = {FORCE_WRITE_INF, 0, 0.0, 0.0};
    RKMPM_CHECK(rkmpm_sim_set_body_force(f.sim, body_force, &data));
    CALL(f.sim, rkmpm_sim_step(f.sim, stable_dt(&f, 0.5)));
    drop(&f);
  }
  ROW("step.non_finite", RKMPM_ERR_NON_FINITE) {
    /* Heavy particles and a finite but huge body force: the grid force sum overflows. */
    Fixture f = block_with(2, 1.0e4, 1.0e6);
    ForceData data = {FORCE_HUGE, 0, 0.0, 0.0};
    RKMPM_CHECK(rkmpm_sim_set_body_force(f.sim, body_force, &data));
    CALL(f.sim, rkmpm_sim_step(f.sim, stable_dt(&f, 0.5)));
    drop(&f);
  }
  ROW("step.inverted_particle", RKMPM_ERR_INVERTED_PARTICLE) {
    /* A converging body force that folds the block over in x within one step (F_xx = -2). */
    Fixture f = block(2);
    const double dt = stable_dt(&f, 0.5);
    ForceData data = {FORCE_CONVERGE, 0, 3.0 / (dt * dt), 0.5};
    RKMPM_CHECK(rkmpm_sim_set_body_force(f.sim, body_force, &data));
    CALL(f.sim, rkmpm_sim_step(f.sim, dt));
    drop(&f);
  }
  ROW("step.outside_grid", RKMPM_ERR_OUTSIDE_GRID) {
    Fixture f = empty_sim(2);
    RKMPM_CHECK(rkmpm_sim_add_material_linear_elastic(f.sim, 1.0, 100.0, 0.3, &f.material));
    const double x[2] = {0.99, 0.5}, v[2] = {1000.0, 0.0}, vol[1] = {H * H / 4.0};
    RKMPM_CHECK(rkmpm_sim_add_particles(f.sim, f.material, 1, x, vol, v));
    CALL(f.sim, rkmpm_sim_step(f.sim, stable_dt(&f, 1.0)));
    drop(&f);
  }
  ROW("step.boundary_point_leaves_grid", RKMPM_ERR_OUTSIDE_GRID) {
    /* A boundary point with a (zero) traction on the face x = 1, carried out by the grid. */
    Fixture f = empty_sim(2);
    RKMPM_CHECK(rkmpm_sim_add_material_linear_elastic(f.sim, 1.0, 100.0, 0.3, &f.material));
    const double x[2] = {0.975, 0.5}, v[2] = {5.0, 0.0}, vol[1] = {H * H / 4.0};
    RKMPM_CHECK(rkmpm_sim_add_particles(f.sim, f.material, 1, x, vol, v));
    const double bx[2] = {1.0, 0.5}, bn[2] = {0.05, 0.0}, bt[2] = {0.0, 0.0};
    RKMPM_CHECK(rkmpm_sim_add_boundary_points(f.sim, 1, bx, bn, bt));
    CALL(f.sim, rkmpm_sim_step(f.sim, stable_dt(&f, 0.5)));
    drop(&f);
  }
  ROW("step.wall_needs_cells", RKMPM_ERR_INVALID_ARGUMENT) {
    /* A fixed wall across an axis of one cell; the quadratic B-spline needs two ghost layers. */
    const size_t cells[2] = {1, 10};
    RkmpmSim *sim = NULL;
    RKMPM_CHECK(rkmpm_sim_new(2, ORIGIN, cells, H, &sim));
    uint32_t m = 0;
    RKMPM_CHECK(rkmpm_sim_add_material_linear_elastic(sim, 1.0, 100.0, 0.3, &m));
    const double x[2] = {0.05, 0.5}, vol[1] = {H * H / 4.0};
    RKMPM_CHECK(rkmpm_sim_add_particles(sim, m, 1, x, vol, NULL));
    RKMPM_CHECK(rkmpm_sim_set_boundary(sim, 0, -1, RKMPM_BOUNDARY_FIXED, 0.0));
    double dt = 0.0;
    RKMPM_CHECK(rkmpm_sim_stable_dt(sim, 0.5, &dt));
    CALL(sim, rkmpm_sim_step(sim, dt));
    rkmpm_sim_free(sim);
  }
  ROW("step.apic_with_rk2", RKMPM_ERR_UNSUPPORTED) {
    Fixture f = block(2);
    RKMPM_CHECK(rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_RK, 2, 3.0)); /* transfer: APIC */
    CALL(f.sim, rkmpm_sim_step(f.sim, stable_dt(&f, 0.5)));
    /* A refused step is not a first step: the options can still change. */
    RKMPM_CHECK(rkmpm_sim_set_transfer(f.sim, RKMPM_TRANSFER_PIC_FLIP, 0.0));
    drop(&f);
  }
  ROW("step.mls_without_quadratic_or_cubic_bspline", RKMPM_ERR_UNSUPPORTED) {
    Fixture f = block(2);
    RKMPM_CHECK(rkmpm_sim_set_transfer(f.sim, RKMPM_TRANSFER_MLS, 0.0));
    RKMPM_CHECK(rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_LINEAR, 0, 0.0));
    CALL(f.sim, rkmpm_sim_step(f.sim, stable_dt(&f, 0.5)));
    /* RK of order 1 with a support other than 2 (with 2 it is the cubic B-spline, which MLS takes). */
    RKMPM_CHECK(rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_RK, 1, 2.5));
    CALL(f.sim, rkmpm_sim_step(f.sim, stable_dt(&f, 0.5)));
    /* With the quadratic B-spline it runs. */
    RKMPM_CHECK(rkmpm_sim_set_shape(f.sim, RKMPM_SHAPE_BSPLINE2, 0, 0.0));
    RKMPM_CHECK(rkmpm_sim_step(f.sim, stable_dt(&f, 0.5)));
    drop(&f);
  }
  ROW("step.mls_with_vc", RKMPM_ERR_UNSUPPORTED) {
    Fixture f = block(2);
    RKMPM_CHECK(rkmpm_sim_set_transfer(f.sim, RKMPM_TRANSFER_MLS, 0.0));
    RKMPM_CHECK(rkmpm_sim_set_integration(f.sim, RKMPM_INTEGRATION_VC, 1));
    CALL(f.sim, rkmpm_sim_step(f.sim, stable_dt(&f, 0.5)));
    drop(&f);
  }
  ROW("step.contact_with_musl", RKMPM_ERR_UNSUPPORTED) {
    Fixture f = block(2);
    RKMPM_CHECK(rkmpm_sim_set_contact(f.sim, 1, 0.2));
    RKMPM_CHECK(rkmpm_sim_set_scheme(f.sim, RKMPM_SCHEME_MUSL));
    CALL(f.sim, rkmpm_sim_step(f.sim, stable_dt(&f, 0.5)));
    drop(&f);
  }
  ROW("step.contact_with_boundary_points", RKMPM_ERR_UNSUPPORTED) {
    Fixture f = block(2);
    RKMPM_CHECK(rkmpm_sim_set_contact(f.sim, 1, 0.2));
    const double bx[2] = {0.4, 0.5}, bn[2] = {-0.05, 0.0};
    RKMPM_CHECK(rkmpm_sim_add_boundary_points(f.sim, 1, bx, bn, NULL));
    CALL(f.sim, rkmpm_sim_step(f.sim, stable_dt(&f, 0.5)));
    drop(&f);
  }
  ROW("step.rigid_without_contact", RKMPM_ERR_UNSUPPORTED) {
    Fixture f = block(2);
    const double v[2] = {0.0, -1.0};
    uint32_t rigid = 0;
    RKMPM_CHECK(rkmpm_sim_add_material_rigid(f.sim, 1.0, v, &rigid));
    CALL(f.sim, rkmpm_sim_step(f.sim, stable_dt(&f, 0.5)));
    drop(&f);
  }
  ROW("step.dt_below_time_resolution", RKMPM_ERR_INVALID_ARGUMENT) {
    /* At t = 1e20 a step of the stable size (about 1e-3) cannot change the time. */
    Fixture f = resting_block_at(1e20);
    CALL(f.sim, rkmpm_sim_step(f.sim, stable_dt(&f, 0.5)));
    drop(&f);
  }

  /* ---- rkmpm_sim_advance ---- */
  ROW("advance.null_sim", RKMPM_ERR_NULL_POINTER) {
    uint64_t n = 77;
    CALL(NULL, rkmpm_sim_advance(NULL, 1e-3, 0.5, &n));
    EXPECT(n == 77, "wrote the step count after a NULL handle");
  }
  ROW("advance.misaligned_out_steps", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_advance(f.sim, 1e-3, 0.5, misaligned(raw)));
    drop(&f);
  }
  ROW("advance.null_out_steps", RKMPM_OK) {
    Fixture f = block(2);
    const double duration = 3.5 * stable_dt(&f, 0.5);
    CALL(NULL, rkmpm_sim_advance(f.sim, duration, 0.5, NULL)); /* advances: a success */
    double t = 0.0;
    RKMPM_CHECK(rkmpm_sim_time(f.sim, &t));
    EXPECT(t == duration, "advanced to %.17g instead of %.17g", t, duration);
    drop(&f);
  }
  ROW("advance.duration_not_positive", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    const double durations[3] = {0.0, -0.0, -1e-3};
    for (int k = 0; k < 3; ++k) {
      uint64_t n = 77;
      CALL(f.sim, rkmpm_sim_advance(f.sim, durations[k], 0.5, &n));
      EXPECT(n == 0, "wrote %llu steps", (unsigned long long)n);
    }
    drop(&f);
  }
  ROW("advance.duration_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    uint64_t n = 77;
    CALL(f.sim, rkmpm_sim_advance(f.sim, NAN, 0.5, &n));
    EXPECT(n == 0, "wrote %llu steps", (unsigned long long)n);
    drop(&f);
  }
  ROW("advance.duration_infinite", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(3);
    uint64_t n = 77;
    CALL(f.sim, rkmpm_sim_advance(f.sim, INFINITY, 0.5, &n));
    EXPECT(n == 0, "wrote %llu steps", (unsigned long long)n);
    drop(&f);
  }
  ROW("advance.duration_below_resolution", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = resting_block_at(1.0);
    uint64_t n = 77;
    CALL(f.sim, rkmpm_sim_advance(f.sim, 1e-20, 0.5, &n));
    EXPECT(n == 0, "wrote %llu steps", (unsigned long long)n);
    drop(&f);
  }
  ROW("advance.cfl_out_of_range", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    const double cfl[3] = {0.0, 1.5, -0.5};
    for (int k = 0; k < 3; ++k) {
      uint64_t n = 77;
      CALL(f.sim, rkmpm_sim_advance(f.sim, 1e-2, cfl[k], &n));
      EXPECT(n == 0, "wrote %llu steps", (unsigned long long)n);
    }
    drop(&f);
  }
  ROW("advance.cfl_nan", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    uint64_t n = 77;
    CALL(f.sim, rkmpm_sim_advance(f.sim, 1e-2, NAN, &n));
    CALL(f.sim, rkmpm_sim_advance(f.sim, 1e-2, INFINITY, &n));
    EXPECT(n == 0, "wrote %llu steps", (unsigned long long)n);
    drop(&f);
  }
  ROW("advance.no_particles", RKMPM_ERR_INVALID_STATE) {
    Fixture f = empty_sim(2);
    uint64_t n = 77;
    CALL(f.sim, rkmpm_sim_advance(f.sim, 1e-2, 0.5, &n));
    EXPECT(n == 0, "wrote %llu steps", (unsigned long long)n);
    drop(&f);
  }
  ROW("advance.estimate_above_bound", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    uint64_t n = 77;
    CALL(f.sim, rkmpm_sim_advance(f.sim, 1e300, 0.5, &n));
    EXPECT(n == 0, "wrote %llu steps", (unsigned long long)n);
    char message[512];
    rkmpm_last_error_message(message, sizeof message);
    EXPECT(strstr(message, "above the bound of 1000000000 steps per advance") != NULL,
           "no bound in: %s", message);
    RKMPM_CHECK(rkmpm_sim_set_max_steps_per_advance(f.sim, 10));
    n = 77;
    CALL(f.sim, rkmpm_sim_advance(f.sim, 24.5 * stable_dt(&f, 0.5), 0.5, &n));
    EXPECT(n == 0, "wrote %llu steps", (unsigned long long)n);
    rkmpm_last_error_message(message, sizeof message);
    EXPECT(strstr(message, "needs about 2.500e1 steps") != NULL, "no estimate in: %s", message);
    drop(&f);
  }
  ROW("advance.first_step_fails", RKMPM_ERR_CALLBACK) {
    Fixture f = block(2);
    ForceData data = {FORCE_RETURN_ERROR, 0, 0.0, 0.0};
    RKMPM_CHECK(rkmpm_sim_set_body_force(f.sim, body_force, &data));
    uint64_t n = 77;
    CALL(f.sim, rkmpm_sim_advance(f.sim, 10.0 * stable_dt(&f, 0.5), 0.5, &n));
    EXPECT(n == 0, "wrote %llu steps", (unsigned long long)n);
    drop(&f);
  }
  ROW("advance.stopped_by_progress", RKMPM_ERR_CALLBACK) {
    /* The progress callback stops the run after its second call: two steps stand. */
    Fixture f = block(2);
    ProgressData data = {0, 2, 0, 0.0, 0.0};
    RKMPM_CHECK(rkmpm_sim_set_progress(f.sim, progress, &data));
    uint64_t n = 77;
    CALL(NULL, rkmpm_sim_advance(f.sim, 10.0 * stable_dt(&f, 0.5), 0.5, &n));
    EXPECT(n == 2 && data.calls == 2, "%llu steps, %d calls", (unsigned long long)n, data.calls);
    uint64_t steps = 0;
    RKMPM_CHECK(rkmpm_sim_step_count(f.sim, &steps));
    EXPECT(steps == 2, "%llu steps taken", (unsigned long long)steps);
    drop(&f);
  }
  ROW("advance.later_step_fails", RKMPM_ERR_CALLBACK) {
    /* The third step fails: the first two stay taken (documented), the third leaves nothing. */
    Fixture f = block(2);
    ForceData data = {FORCE_FAIL_THIRD, 0, 0.0, 0.0};
    RKMPM_CHECK(rkmpm_sim_set_body_force(f.sim, body_force, &data));
    const double duration = 10.0 * stable_dt(&f, 0.5);
    Fixture twin = block(2); /* the same run, two steps without failure */
    ForceData twin_data = {FORCE_COUNT, 0, 0.0, 0.0};
    RKMPM_CHECK(rkmpm_sim_set_body_force(twin.sim, body_force, &twin_data));
    uint64_t n = 77;
    CALL(NULL, rkmpm_sim_advance(f.sim, duration, 0.5, &n));
    EXPECT(n == 2, "wrote %llu steps, expected 2", (unsigned long long)n);
    RKMPM_CHECK(rkmpm_sim_step(twin.sim, stable_dt(&twin, 0.5)));
    RKMPM_CHECK(rkmpm_sim_step(twin.sim, stable_dt(&twin, 0.5)));
    Snapshot expected = snapshot_take(twin.sim);
    expect_unchanged(&expected, f.sim, "the state after the two good steps", __LINE__);
    snapshot_release(&expected);
    drop(&twin);
    drop(&f);
  }
}

static void output_rows(void) {
  _Alignas(8) unsigned char raw[64] = {0};
  double buf[64 * 9 + 8];
  const double mark = -12345.0;

  /* ---- rkmpm_sim_field_len ---- */
  ROW("field_len.null_sim", RKMPM_ERR_NULL_POINTER) {
    size_t n = 77;
    CALL(NULL, rkmpm_sim_field_len(NULL, RKMPM_FIELD_MASS, &n));
    EXPECT(n == 77, "wrote the output after a failure");
  }
  ROW("field_len.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_field_len(f.sim, RKMPM_FIELD_STRESS, NULL));
    drop(&f);
  }
  ROW("field_len.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_field_len(f.sim, RKMPM_FIELD_STRESS, misaligned(raw)));
    drop(&f);
  }
  ROW("field_len.unknown_field", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    size_t n = 77;
    CALL(f.sim, rkmpm_sim_field_len(f.sim, 11, &n));
    CALL(f.sim, rkmpm_sim_field_len(f.sim, UINT32_MAX, &n));
    EXPECT(n == 77, "wrote the output after a failure");
    drop(&f);
  }

  /* ---- rkmpm_sim_get_particles ---- */
  ROW("get_particles.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_get_particles(NULL, RKMPM_FIELD_POSITION, buf, 64));
  }
  ROW("get_particles.unknown_field", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    for (size_t i = 0; i < sizeof buf / sizeof buf[0]; ++i) {
      buf[i] = mark;
    }
    CALL(f.sim, rkmpm_sim_get_particles(f.sim, 11, buf, sizeof buf / sizeof buf[0]));
    CALL(f.sim, rkmpm_sim_get_particles(f.sim, UINT32_MAX, buf, sizeof buf / sizeof buf[0]));
    EXPECT(buf[0] == mark, "wrote into the buffer");
    drop(&f);
  }
  ROW("get_particles.buffer_too_small", RKMPM_ERR_BUFFER_TOO_SMALL) {
    for (uint32_t dim = 2; dim <= 3; ++dim) {
      Fixture f = block(dim);
      for (RkmpmField field = 0; field < SNAPSHOT_FIELDS; ++field) {
        size_t need = 0;
        RKMPM_CHECK(rkmpm_sim_field_len(f.sim, field, &need));
        for (size_t i = 0; i < sizeof buf / sizeof buf[0]; ++i) {
          buf[i] = mark;
        }
        CALL(f.sim, rkmpm_sim_get_particles(f.sim, field, buf, need - 1));
        int untouched = 1;
        for (size_t i = 0; i < sizeof buf / sizeof buf[0]; ++i) {
          untouched = untouched && buf[i] == mark;
        }
        EXPECT(untouched, "%uD field %u: a too-small buffer was written to", (unsigned)dim,
               (unsigned)field);
      }
      drop(&f);
    }
  }
  ROW("get_particles.null_out_zero_len", RKMPM_ERR_BUFFER_TOO_SMALL) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_get_particles(f.sim, RKMPM_FIELD_MASS, NULL, 0));
    drop(&f);
  }
  ROW("get_particles.null_out", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    size_t need = 0;
    RKMPM_CHECK(rkmpm_sim_field_len(f.sim, RKMPM_FIELD_VELOCITY, &need));
    CALL(f.sim, rkmpm_sim_get_particles(f.sim, RKMPM_FIELD_VELOCITY, NULL, need));
    CALL(f.sim, rkmpm_sim_get_particles(f.sim, RKMPM_FIELD_VELOCITY, NULL, SIZE_MAX));
    drop(&f);
  }
  ROW("get_particles.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    size_t need = 0;
    RKMPM_CHECK(rkmpm_sim_field_len(f.sim, RKMPM_FIELD_MASS, &need));
    CALL(f.sim, rkmpm_sim_get_particles(f.sim, RKMPM_FIELD_MASS, misaligned(buf), need));
    drop(&f);
  }
  ROW("get_particles.huge_len", RKMPM_OK) {
    Fixture f = block(3);
    size_t need = 0;
    RKMPM_CHECK(rkmpm_sim_field_len(f.sim, RKMPM_FIELD_STRESS, &need));
    for (size_t i = 0; i < sizeof buf / sizeof buf[0]; ++i) {
      buf[i] = mark;
    }
    CALL(f.sim, rkmpm_sim_get_particles(f.sim, RKMPM_FIELD_STRESS, buf, SIZE_MAX));
    EXPECT(need + 1 <= sizeof buf / sizeof buf[0] && buf[need] == mark && buf[need - 1] != mark,
           "did not write exactly the %zu values", need);
    drop(&f);
  }
  ROW("get_particles.no_particles", RKMPM_OK) {
    Fixture f = empty_sim(2);
    CALL(f.sim, rkmpm_sim_get_particles(f.sim, RKMPM_FIELD_STRESS, NULL, 0));
    drop(&f);
  }
}

static void file_rows(void) {
  const char *const bad_utf8 = "\xff\xfe.out";
  char dir[1024];
  snprintf(dir, sizeof dir, "%s", scratch("api_checks_a_directory"));
  mkdir(dir, 0755);
  char dir_tmp[1100];
  snprintf(dir_tmp, sizeof dir_tmp, "%s.tmp", dir);
  remove(dir_tmp);

  /* ---- rkmpm_sim_save ---- */
  ROW("save.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_save(NULL, scratch("api_checks_never.chk")));
    EXPECT(!file_exists(scratch("api_checks_never.chk")), "a file was written");
  }
  ROW("save.null_path", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_save(f.sim, NULL));
    drop(&f);
  }
  ROW("save.non_utf8_path", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_save(f.sim, bad_utf8));
    drop(&f);
  }
  ROW("save.missing_directory", RKMPM_ERR_IO) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_save(f.sim, scratch("api-checks-no-such-directory/run.chk")));
    drop(&f);
  }
  ROW("save.path_is_directory", RKMPM_ERR_IO) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_save(f.sim, dir));
    EXPECT(!file_exists(dir_tmp), "the failed save left %s behind", dir_tmp);
    remove(dir_tmp);
    drop(&f);
  }
  ROW("save.empty_path", RKMPM_ERR_IO) {
    Fixture f = block(2);
    remove(".tmp");
    CALL(f.sim, rkmpm_sim_save(f.sim, ""));
    EXPECT(!file_exists(".tmp"), "the failed save left .tmp behind in the working directory");
    remove(".tmp");
    drop(&f);
  }

  /* ---- rkmpm_sim_load ---- */
  /* A valid 2D checkpoint with the PIC transfer, and damaged copies of it. */
  char good[1024];
  snprintf(good, sizeof good, "%s", scratch("api_checks_good.chk"));
  {
    Fixture f = block(2);
    RKMPM_CHECK(rkmpm_sim_set_transfer(f.sim, RKMPM_TRANSFER_PIC_FLIP, 0.0));
    take_step(&f);
    RKMPM_CHECK(rkmpm_sim_save(f.sim, good));
    drop(&f);
    RkmpmSim *back = NULL;
    RKMPM_CHECK(rkmpm_sim_load(good, &back));
    rkmpm_sim_free(back);
  }
  size_t len = 0;
  unsigned char *bytes = read_file(good, &len);
  unsigned char *edit = malloc(len);
  if (edit == NULL) {
    fprintf(stderr, "out of memory\n");
    exit(EXIT_FAILURE);
  }
  RkmpmSim *const sentinel = (RkmpmSim *)(uintptr_t)&rows_ok;

  ROW("load.null_out", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_load(good, NULL));
  }
  ROW("load.misaligned_out", RKMPM_ERR_INVALID_ARGUMENT) {
    _Alignas(8) unsigned char raw[32] = {0};
    CALL(NULL, rkmpm_sim_load(good, misaligned(raw)));
    EXPECT(raw[1] == 0 && raw[8] == 0, "wrote through a misaligned out pointer");
  }
  ROW("load.null_path", RKMPM_ERR_NULL_POINTER) {
    RkmpmSim *out = sentinel;
    CALL(NULL, rkmpm_sim_load(NULL, &out));
    EXPECT(out == NULL, "*out must be NULL after a failure");
  }
  ROW("load.non_utf8_path", RKMPM_ERR_INVALID_ARGUMENT) {
    load_refuses(bad_utf8);
  }
  ROW("load.missing_file", RKMPM_ERR_IO) {
    load_refuses(scratch("api_checks_no_such_file.chk"));
  }
  ROW("load.directory", RKMPM_ERR_IO) {
    load_refuses(dir);
  }
  ROW("load.empty_file", RKMPM_ERR_CORRUPT_FILE) {
    write_file(scratch("api_checks_empty.chk"), bytes, 0);
    load_refuses(scratch("api_checks_empty.chk"));
  }
  ROW("load.not_a_checkpoint", RKMPM_ERR_CORRUPT_FILE) {
    memcpy(edit, bytes, len);
    memcpy(edit, "RKMPMCHX", 8);
    write_file(scratch("api_checks_magic.chk"), edit, len);
    load_refuses(scratch("api_checks_magic.chk"));
    const unsigned char text[] = "# not a checkpoint, but long enough to hold a frame\n";
    write_file(scratch("api_checks_text.chk"), text, sizeof text - 1);
    load_refuses(scratch("api_checks_text.chk"));
  }
  ROW("load.truncated", RKMPM_ERR_CORRUPT_FILE) {
    write_file(scratch("api_checks_truncated.chk"), bytes, len - 10);
    load_refuses(scratch("api_checks_truncated.chk"));
    write_file(scratch("api_checks_truncated.chk"), bytes, 27);
    load_refuses(scratch("api_checks_truncated.chk"));
  }
  ROW("load.bad_checksum", RKMPM_ERR_CORRUPT_FILE) {
    memcpy(edit, bytes, len);
    edit[len / 2] ^= 0x10;
    write_file(scratch("api_checks_crc.chk"), edit, len);
    load_refuses(scratch("api_checks_crc.chk"));
  }
  ROW("load.newer_version", RKMPM_ERR_UNSUPPORTED) {
    memcpy(edit, bytes, len);
    edit[8] += 1;
    write_file(scratch("api_checks_version.chk"), edit, len);
    load_refuses(scratch("api_checks_version.chk"));
  }
  ROW("load.bad_dimension", RKMPM_ERR_CORRUPT_FILE) {
    memcpy(edit, bytes, len);
    edit[12] = 4;
    write_file(scratch("api_checks_dim.chk"), edit, len);
    load_refuses(scratch("api_checks_dim.chk"));
  }
  ROW("load.invalid_value", RKMPM_ERR_CORRUPT_FILE) {
    /* Payload: origin (2 x 8), cells (2 x 8), cell size (8) at payload offset 32. A cell size
       of -1 under a valid checksum. */
    memcpy(edit, bytes, len);
    const double h = -1.0;
    memcpy(edit + 24 + 32, &h, sizeof h);
    reframe(edit, len);
    write_file(scratch("api_checks_value.chk"), edit, len);
    load_refuses(scratch("api_checks_value.chk"));
  }
  ROW("load.inconsistent_arrays", RKMPM_ERR_CORRUPT_FILE) {
    /* The transfer tag (payload offset 48) turned from PIC/FLIP (0, then its f64 ratio) into
       APIC (1), under a valid checksum: the file says APIC but holds no affine matrices. */
    const size_t at = 24 + 48;
    memcpy(edit, bytes, at);
    edit[at] = 1;
    edit[at + 1] = edit[at + 2] = edit[at + 3] = 0;
    memcpy(edit + at + 4, bytes + at + 12, len - (at + 12));
    reframe(edit, len - 8);
    write_file(scratch("api_checks_arrays.chk"), edit, len - 8);
    load_refuses(scratch("api_checks_arrays.chk"));
  }
  free(edit);
  free(bytes);
  const char *const written[] = {"api_checks_good.chk",  "api_checks_empty.chk",
                                 "api_checks_magic.chk", "api_checks_text.chk",
                                 "api_checks_truncated.chk", "api_checks_crc.chk",
                                 "api_checks_version.chk",   "api_checks_dim.chk",
                                 "api_checks_value.chk",     "api_checks_arrays.chk"};
  for (size_t k = 0; k < sizeof written / sizeof written[0]; ++k) {
    remove(scratch(written[k]));
  }

  /* ---- rkmpm_sim_set_vtk_format ---- */
  ROW("set_vtk_format.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_set_vtk_format(NULL, RKMPM_VTK_ASCII));
  }
  ROW("set_vtk_format.unknown_format", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_set_vtk_format(f.sim, 2));
    CALL(f.sim, rkmpm_sim_set_vtk_format(f.sim, UINT32_MAX));
    EXPECT(rkmpm_sim_write_vtk(f.sim, scratch("api_checks_format.vtu")) == RKMPM_OK,
           "the write after a refused format failed");
    EXPECT(file_contains(scratch("api_checks_format.vtu"), "encoding=\"raw\""),
           "the format changed although it was refused");
    remove(scratch("api_checks_format.vtu"));
    drop(&f);
  }
  /* ---- rkmpm_sim_write_vtk ---- */
  ROW("write_vtk.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_write_vtk(NULL, scratch("api_checks_never.vtu")));
    EXPECT(!file_exists(scratch("api_checks_never.vtu")), "a file was written");
  }
  ROW("write_vtk.null_path", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_write_vtk(f.sim, NULL));
    drop(&f);
  }
  ROW("write_vtk.non_utf8_path", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_write_vtk(f.sim, bad_utf8));
    drop(&f);
  }
  ROW("write_vtk.missing_directory", RKMPM_ERR_IO) {
    Fixture f = block(3);
    CALL(f.sim, rkmpm_sim_write_vtk(f.sim, scratch("api-checks-no-such-directory/p.vtu")));
    drop(&f);
  }
  ROW("write_vtk.path_is_directory", RKMPM_ERR_IO) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_write_vtk(f.sim, dir));
    EXPECT(!file_exists(dir_tmp), "the failed write left %s behind", dir_tmp);
    remove(dir_tmp);
    drop(&f);
  }
  ROW("write_vtk.empty_path", RKMPM_ERR_IO) {
    Fixture f = block(2);
    remove(".tmp");
    CALL(f.sim, rkmpm_sim_write_vtk(f.sim, ""));
    EXPECT(!file_exists(".tmp"), "the failed write left .tmp behind in the working directory");
    remove(".tmp");
    drop(&f);
  }

  /* ---- rkmpm_sim_write_vtk_frame ---- */
  ROW("write_vtk_frame.null_sim", RKMPM_ERR_NULL_POINTER) {
    CALL(NULL, rkmpm_sim_write_vtk_frame(NULL, scratch("api_checks_never")));
    EXPECT(!file_exists(scratch("api_checks_never.pvd")), "a file was written");
  }
  ROW("write_vtk_frame.null_prefix", RKMPM_ERR_NULL_POINTER) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_write_vtk_frame(f.sim, NULL));
    drop(&f);
  }
  ROW("write_vtk_frame.non_utf8_prefix", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_write_vtk_frame(f.sim, bad_utf8));
    drop(&f);
  }
  ROW("write_vtk_frame.missing_directory", RKMPM_ERR_IO) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_write_vtk_frame(f.sim, scratch("api-checks-no-such-directory/s")));
    drop(&f);
  }
  ROW("write_vtk_frame.empty_prefix", RKMPM_ERR_INVALID_ARGUMENT) {
    Fixture f = block(2);
    CALL(f.sim, rkmpm_sim_write_vtk_frame(f.sim, ""));
    EXPECT(!file_exists("frame_00000.vtu") && !file_exists(".pvd"),
           "an empty prefix wrote frame_00000.vtu and .pvd into the working directory");
    remove("frame_00000.vtu");
    remove(".pvd");
    drop(&f);
  }
  remove(dir);
}

/* ---- calls that may not return ------------------------------------------------------------ */

typedef struct {
  RkmpmSim *sim;
  double duration;
  uint64_t steps;
  RkmpmStatus status;
  char message[1024];
  atomic_int done;
} AdvanceJob;

static int advance_job(void *arg) {
  AdvanceJob *job = arg;
  job->status = rkmpm_sim_advance(job->sim, job->duration, 0.5, &job->steps);
  rkmpm_last_error_message(job->message, sizeof job->message);
  atomic_store(&job->done, 1);
  return 0;
}

/* Checks a finished job against the current row; returns 1 when it has not finished. */
static int finish_advance_job(AdvanceJob *job, thrd_t thread, Fixture *f, Snapshot *before) {
  int hung = 0;
  if (!atomic_load(&job->done)) {
    problem(__LINE__, "rkmpm_sim_advance did not return within 5 s (a loop without end)");
    hung = 1;
  } else {
    thrd_join(thread, NULL);
    check_result(job->status, job->message, "rkmpm_sim_advance", __LINE__);
    EXPECT(job->steps == 0, "wrote %llu steps", (unsigned long long)job->steps);
    expect_unchanged(before, f->sim, "rkmpm_sim_advance", __LINE__);
    drop(f);
  }
  snapshot_release(before);
  return hung;
}

/* Rows whose call could loop without end (a step that cannot move the time): each runs
   rkmpm_sim_advance on its own thread and is given 5 seconds. When one does not return, the
   driver reports it and stops at once with _Exit (the call cannot be interrupted), after every
   other row has run. */
static void advance_end_rows(void) {
  static AdvanceJob jobs[2];
  static Fixture fixtures[2];
  Snapshot before[2];
  thrd_t threads[2];
  /* 0: the end time time + duration overflows to +inf; 1: the stable step is below the
     resolution of the time, so no step moves it. Particles at rest: nothing else stops the run. */
  fixtures[0] = resting_block_at(DBL_MAX);
  jobs[0].duration = DBL_MAX;
  fixtures[1] = resting_block_at(1e20);
  jobs[1].duration = 1e6;
  for (int k = 0; k < 2; ++k) {
    jobs[k].sim = fixtures[k].sim;
    jobs[k].steps = 77;
    atomic_init(&jobs[k].done, 0);
    before[k] = snapshot_take(fixtures[k].sim);
    if (thrd_create(&threads[k], advance_job, &jobs[k]) != thrd_success) {
      fprintf(stderr, "thrd_create failed\n");
      exit(EXIT_FAILURE);
    }
  }
  const struct timespec tick = {0, 10 * 1000 * 1000};
  for (int waited = 0; waited < 500 && !(atomic_load(&jobs[0].done) && atomic_load(&jobs[1].done));
       ++waited) {
    thrd_sleep(&tick, NULL);
  }
  int hung = 0;
  ROW("advance.end_time_overflow", RKMPM_ERR_INVALID_ARGUMENT) {
    hung |= finish_advance_job(&jobs[0], threads[0], &fixtures[0], &before[0]);
  }
  ROW("advance.step_below_time_resolution", RKMPM_ERR_INVALID_ARGUMENT) {
    hung |= finish_advance_job(&jobs[1], threads[1], &fixtures[1], &before[1]);
  }
  if (hung) {
    printf("%d rows: %d ok, %d failed (stopped: a call did not return)\n", rows_ok + rows_failed,
           rows_ok, rows_failed);
    fflush(stdout);
    fflush(stderr);
    _Exit(EXIT_FAILURE);
  }
}

int main(int argc, char **argv) {
  setvbuf(stdout, NULL, _IOLBF, 0);
  verbose = getenv("RKMPM_API_CHECKS_VERBOSE") != NULL;
  if (argc > 1) {
    scratch_dir = argv[1];
    mkdir(scratch_dir, 0755);
  }
  printf("rkmpm %s: the checks of docs/C_API_CHECKS.md\n", rkmpm_version());
  library_rows();
  lifetime_rows();
  option_rows();
  material_rows();
  particle_rows();
  step_rows();
  output_rows();
  file_rows();
  advance_end_rows();
  printf("%d rows: %d ok, %d failed\n", rows_ok + rows_failed, rows_ok, rows_failed);
  return rows_failed == 0 ? EXIT_SUCCESS : EXIT_FAILURE;
}
