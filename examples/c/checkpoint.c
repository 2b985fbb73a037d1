/*
 * Checkpoint and restart from C: a Drucker-Prager block slumping on a friction floor is run
 * 200 steps straight, and 80 steps, saved, loaded into a new handle (the original freed) and run
 * 120 more. Every particle field must agree bit for bit. Then a damaged copy of the file must be
 * refused with RKMPM_ERR_CORRUPT_FILE and give no handle.
 *
 * Usage: checkpoint_c <scratch directory>
 */
#include "rkmpm_check.h"

#include <stdint.h>
#include <string.h>

static RkmpmSim *make_block(void) {
  RkmpmSim *sim = NULL;
  const double origin[2] = {0.0, 0.0};
  const size_t cells[2] = {24, 12};
  RKMPM_CHECK(rkmpm_sim_new(2, origin, cells, 0.05, &sim));
  uint32_t soil = 0;
  RKMPM_CHECK(rkmpm_sim_add_material_drucker_prager(sim, 2650.0, 1e6, 0.3, 25.0, 100.0, 5.0, &soil));
  RKMPM_CHECK(rkmpm_sim_set_boundary(sim, 1, -1, RKMPM_BOUNDARY_FRICTION, 0.4));
  const double g[2] = {0.0, -9.81};
  RKMPM_CHECK(rkmpm_sim_set_gravity(sim, g));
  double x[2 * 256], vol[256];
  for (int j = 0; j < 16; ++j) {
    for (int i = 0; i < 16; ++i) {
      x[2 * (16 * j + i)] = 0.4 + 0.025 * (i + 0.5);
      x[2 * (16 * j + i) + 1] = 0.025 * (j + 0.5);
      vol[16 * j + i] = 0.025 * 0.025;
    }
  }
  RKMPM_CHECK(rkmpm_sim_add_particles(sim, soil, 256, x, vol, NULL));
  return sim;
}

static void advance(RkmpmSim *sim, int steps) {
  for (int k = 0; k < steps; ++k) {
    double dt = 0.0;
    RKMPM_CHECK(rkmpm_sim_stable_dt(sim, 0.3, &dt));
    RKMPM_CHECK(rkmpm_sim_step(sim, dt));
  }
}

static double *field(const RkmpmSim *sim, RkmpmField f, size_t *len) {
  RKMPM_CHECK(rkmpm_sim_field_len(sim, f, len));
  double *out = malloc((*len + 1) * sizeof(double));
  if (out == NULL) {
    exit(EXIT_FAILURE);
  }
  RKMPM_CHECK(rkmpm_sim_get_particles(sim, f, out, *len));
  return out;
}

int main(int argc, char **argv) {
  if (argc != 2) {
    fprintf(stderr, "usage: %s <scratch directory>\n", argv[0]);
    return EXIT_FAILURE;
  }
  char path[4096], damaged[4096];
  snprintf(path, sizeof path, "%s/block.rkmpm", argv[1]);
  snprintf(damaged, sizeof damaged, "%s/damaged.rkmpm", argv[1]);

  RkmpmSim *straight = make_block();
  advance(straight, 200);

  RkmpmSim *first = make_block();
  advance(first, 80);
  RKMPM_CHECK(rkmpm_sim_save(first, path));
  rkmpm_sim_free(first);
  RkmpmSim *resumed = NULL;
  RKMPM_CHECK(rkmpm_sim_load(path, &resumed));
  advance(resumed, 120);

  int failures = 0;
  for (RkmpmField f = RKMPM_FIELD_POSITION; f <= RKMPM_FIELD_DAMAGE; ++f) {
    size_t na = 0, nb = 0;
    double *a = field(straight, f, &na);
    double *b = field(resumed, f, &nb);
    if (na != nb || memcmp(a, b, na * sizeof(double)) != 0) {
      fprintf(stderr, "FAIL: field %u differs after the restart\n", (unsigned)f);
      ++failures;
    }
    free(a);
    free(b);
  }
  double eps_max = 0.0;
  size_t n = 0;
  double *eps = field(resumed, RKMPM_FIELD_PLASTIC_STRAIN, &n);
  for (size_t p = 0; p < n; ++p) {
    eps_max = eps[p] > eps_max ? eps[p] : eps_max;
  }
  free(eps);
  if (!(eps_max > 0.0)) {
    fprintf(stderr, "FAIL: the block never yielded, so the history was not exercised\n");
    ++failures;
  }

  /* A damaged copy: one byte flipped in the middle. */
  FILE *in = fopen(path, "rb");
  if (in == NULL) {
    return EXIT_FAILURE;
  }
  fseek(in, 0, SEEK_END);
  long size = ftell(in);
  fseek(in, 0, SEEK_SET);
  unsigned char *bytes = malloc((size_t)size);
  if (bytes == NULL || fread(bytes, 1, (size_t)size, in) != (size_t)size) {
    return EXIT_FAILURE;
  }
  fclose(in);
  bytes[size / 2] ^= 0x40;
  FILE *out = fopen(damaged, "wb");
  if (out == NULL || fwrite(bytes, 1, (size_t)size, out) != (size_t)size) {
    return EXIT_FAILURE;
  }
  fclose(out);
  free(bytes);
  RkmpmSim *bad = (RkmpmSim *)1;
  RkmpmStatus status = rkmpm_sim_load(damaged, &bad);
  if (status != RKMPM_ERR_CORRUPT_FILE || bad != NULL) {
    fprintf(stderr, "FAIL: damaged checkpoint gave status %d (%s)\n", (int)status,
            rkmpm_status_str((int32_t)status));
    ++failures;
  }

  rkmpm_sim_free(straight);
  rkmpm_sim_free(resumed);
  printf("checkpoint: %d failures (largest plastic strain %.3e)\n", failures, eps_max);
  return failures == 0 ? EXIT_SUCCESS : EXIT_FAILURE;
}
