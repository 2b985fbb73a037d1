/*
 * Tiny helpers shared by the C example drivers: check every rkmpm call and stop with the status
 * name and the library's last error message when one fails.
 */
#ifndef RKMPM_EXAMPLES_CHECK_H
#define RKMPM_EXAMPLES_CHECK_H

#include "rkmpm.h"

#include <stdio.h>
#include <stdlib.h>

/* The last error message of this thread as a malloc'ed string (never NULL; free it). */
static inline char *rkmpm_example_last_error(void) {
  size_t len = rkmpm_last_error_message(NULL, 0);
  char *buf = malloc(len + 1);
  if (buf == NULL) {
    fprintf(stderr, "out of memory\n");
    exit(EXIT_FAILURE);
  }
  rkmpm_last_error_message(buf, len + 1);
  return buf;
}

static inline void rkmpm_example_fail(const char *call, RkmpmStatus status, const char *file,
                                      int line) {
  char *message = rkmpm_example_last_error();
  fprintf(stderr, "%s:%d: %s failed with status %d (%s): %s\n", file, line, call, (int)status,
          rkmpm_status_str((int32_t)status), message);
  free(message);
  exit(EXIT_FAILURE);
}

/* Evaluates an rkmpm call; on any status but RKMPM_OK prints what failed and exits. */
#define RKMPM_CHECK(call)                                                                          \
  do {                                                                                             \
    RkmpmStatus rkmpm_check_status_ = (call);                                                      \
    if (rkmpm_check_status_ != RKMPM_OK) {                                                         \
      rkmpm_example_fail(#call, rkmpm_check_status_, __FILE__, __LINE__);                          \
    }                                                                                              \
  } while (0)

#endif /* RKMPM_EXAMPLES_CHECK_H */
