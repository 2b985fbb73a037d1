/*
 * Compares two particle files written by the vibrating-bar drivers (C, Fortran, Rust).
 *
 *   usage: compare_particles <file a> <file b> [tolerance, default 1e-12]
 *
 * A file holds one particle per line, whitespace-separated numbers (any notation strtod reads);
 * empty lines and lines starting with '#' are skipped. Fails (exit 1) when the files differ in
 * the number of particle lines, in the number of values on a line, when a value does not parse,
 * or when two values differ by more than the absolute tolerance. Reports the largest difference
 * and how many values are bit-for-bit equal.
 */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define MAX_LINE 4096
#define MAX_VALUES 64

/* Reads the next particle line of `f` into `values`; returns the number of values, 0 at the end
   of the file, -1 on a parse error. */
static int next_line(FILE *f, const char *name, long *line_no, double *values) {
  char line[MAX_LINE];
  while (fgets(line, sizeof line, f) != NULL) {
    ++*line_no;
    if (strchr(line, '\n') == NULL && !feof(f)) {
      fprintf(stderr, "%s:%ld: line longer than %d characters\n", name, *line_no, MAX_LINE - 1);
      return -1;
    }
    char *s = line;
    while (*s == ' ' || *s == '\t') {
      ++s;
    }
    if (*s == '\n' || *s == '\r' || *s == '\0' || *s == '#') {
      continue;
    }
    int n = 0;
    for (;;) {
      while (*s == ' ' || *s == '\t' || *s == '\r' || *s == '\n') {
        ++s;
      }
      if (*s == '\0') {
        break;
      }
      if (n == MAX_VALUES) {
        fprintf(stderr, "%s:%ld: more than %d values\n", name, *line_no, MAX_VALUES);
        return -1;
      }
      char *end = NULL;
      errno = 0;
      values[n] = strtod(s, &end);
      if (end == s || errno == ERANGE ||
          (*end != '\0' && *end != ' ' && *end != '\t' && *end != '\r' && *end != '\n')) {
        fprintf(stderr, "%s:%ld: cannot read a number at \"%.20s\"\n", name, *line_no, s);
        return -1;
      }
      ++n;
      s = end;
    }
    return n;
  }
  return 0;
}

int main(int argc, char **argv) {
  if (argc != 3 && argc != 4) {
    fprintf(stderr, "usage: %s <file a> <file b> [tolerance]\n",
            argc > 0 ? argv[0] : "compare_particles");
    return EXIT_FAILURE;
  }
  double tolerance = 1e-12;
  if (argc == 4) {
    char *end = NULL;
    tolerance = strtod(argv[3], &end);
    if (end == argv[3] || *end != '\0' || !(tolerance >= 0.0)) {
      fprintf(stderr, "bad tolerance \"%s\"\n", argv[3]);
      return EXIT_FAILURE;
    }
  }
  FILE *fa = fopen(argv[1], "r");
  if (fa == NULL) {
    perror(argv[1]);
    return EXIT_FAILURE;
  }
  FILE *fb = fopen(argv[2], "r");
  if (fb == NULL) {
    perror(argv[2]);
    fclose(fa);
    return EXIT_FAILURE;
  }

  long line_a = 0, line_b = 0, particles = 0, values = 0, identical = 0, above = 0;
  double max_diff = 0.0;
  long max_at = 0;
  int ok = 1;
  double a[MAX_VALUES], b[MAX_VALUES];
  for (;;) {
    int na = next_line(fa, argv[1], &line_a, a);
    int nb = next_line(fb, argv[2], &line_b, b);
    if (na < 0 || nb < 0) {
      ok = 0;
      break;
    }
    if (na == 0 && nb == 0) {
      break;
    }
    if (na == 0 || nb == 0) {
      fprintf(stderr, "different number of particles: %s ends after %ld, %s has more\n",
              na == 0 ? argv[1] : argv[2], particles, na == 0 ? argv[2] : argv[1]);
      ok = 0;
      break;
    }
    ++particles;
    if (na != nb) {
      fprintf(stderr, "particle %ld: %d values in %s (line %ld), %d in %s (line %ld)\n",
              particles, na, argv[1], line_a, nb, argv[2], line_b);
      ok = 0;
      break;
    }
    for (int k = 0; k < na; ++k) {
      ++values;
      if (memcmp(&a[k], &b[k], sizeof a[k]) == 0) {
        ++identical;
      }
      double diff = fabs(a[k] - b[k]);
      if (!(diff <= tolerance)) {
        if (above < 10) {
          fprintf(stderr, "particle %ld value %d: %.17g vs %.17g (difference %.3e)\n", particles,
                  k + 1, a[k], b[k], diff);
        }
        ++above;
        ok = 0;
      }
      if (diff > max_diff || diff != diff) {
        max_diff = diff;
        max_at = particles;
      }
    }
  }
  fclose(fa);
  fclose(fb);
  if (ok && particles == 0) {
    fprintf(stderr, "no particles in either file\n");
    ok = 0;
  }
  printf("%s vs %s: %ld particles, %ld values, %ld bit-identical, max |difference| = %.3e "
         "(particle %ld), %ld above the tolerance %.1e\n",
         argv[1], argv[2], particles, values, identical, max_diff, max_at, above, tolerance);
  printf("%s\n", ok ? "files agree" : "FILES DIFFER");
  return ok ? EXIT_SUCCESS : EXIT_FAILURE;
}
