/*
 * hbn firmware example: the estimator step in C, from the files `hbn export --format c` writes
 * (hbn_model.h, hbn_model.c), the header hbn.h and the static library libhbn_ffi.a.
 *
 * Reads `u,y` rows (CSV with a header line) from stdin and writes `x,x_std,flags` rows to
 * stdout, one per input row, with a header line. No allocation: the filter and its work memory
 * are static, sized by the export (HBN_MODEL_WORK_LEN).
 *
 * Build: make -C examples/firmware-c MODEL=DIR   (DIR holds the exported files)
 * Run:   examples/firmware-c/build/hbn-firmware < samples.csv > estimates.csv
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "hbn.h"
#include "hbn_model.h"

static HbnFilter filter;
static double work[HBN_MODEL_WORK_LEN > 0 ? HBN_MODEL_WORK_LEN : 1];

int main(void) {
    size_t needed = hbn_work_len(&hbn_model);
    if (needed == 0 || needed > sizeof work / sizeof work[0]) {
        fprintf(stderr, "hbn-firmware: the model needs %zu doubles of work memory, %zu given\n",
                needed, sizeof work / sizeof work[0]);
        return 1;
    }
    HbnStatus status = hbn_filter_init(&filter, &hbn_model, work, sizeof work / sizeof work[0]);
    if (status != HBN_STATUS_OK) {
        fprintf(stderr, "hbn-firmware: hbn_filter_init failed: %s\n", hbn_status_name(status));
        return 1;
    }
    char line[512];
    if (fgets(line, sizeof line, stdin) == NULL) {
        fprintf(stderr, "hbn-firmware: empty input (expected a `u,y` header line)\n");
        return 1;
    }
    printf("x,x_std,flags\n");
    unsigned long row = 1;
    while (fgets(line, sizeof line, stdin) != NULL) {
        row++;
        if (line[0] == '\n' || line[0] == '\r' || line[0] == '\0') {
            continue;
        }
        char *end = NULL;
        double u = strtod(line, &end);
        if (end == line || *end != ',') {
            fprintf(stderr, "hbn-firmware: line %lu is not `u,y`: %s", row, line);
            return 1;
        }
        char *y_text = end + 1;
        double y = strtod(y_text, &end);
        if (end == y_text) {
            fprintf(stderr, "hbn-firmware: line %lu is not `u,y`: %s", row, line);
            return 1;
        }
        HbnOutput out;
        status = hbn_filter_step(&filter, u, y, &out);
        if (status != HBN_STATUS_OK) {
            fprintf(stderr, "hbn-firmware: hbn_filter_step failed: %s\n", hbn_status_name(status));
            return 1;
        }
        /* %.17g prints every double so that it reads back to the same bits. */
        printf("%.17g,%.17g,%u\n", out.x, out.x_std, (unsigned)out.flags);
    }
    return 0;
}
