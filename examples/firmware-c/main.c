/*
 * hbn firmware example: the estimator step in C, from the files `hbn export --format c` writes
 * (hbn_model.h, hbn_model.c), the header hbn.h and the static library libhbn_ffi.a.
 *
 * Reads CSV from stdin: a header line that names a `u` and a `y` column, then one row per sample
 * at the model's rate. A two-column `u,y` file and the CSV of `hbn estimate --csv` (whose `u`
 * and `y` are the samples its filter ran on) both qualify. Writes `x,x_std,flags` rows to
 * stdout, one per input row, with a header line. No allocation: the filter and its work memory
 * are static, sized by the export (HBN_MODEL_WORK_LEN).
 *
 * Build: make -C examples/firmware-c MODEL=DIR   (DIR holds the exported files)
 * Run:   examples/firmware-c/build/hbn-firmware < est.csv > firmware.csv
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "hbn.h"
#include "hbn_model.h"

static HbnFilter filter;
static double work[HBN_MODEL_WORK_LEN > 0 ? HBN_MODEL_WORK_LEN : 1];
static char line[8192];

/* The index of the column called `name` in the header line, or -1. */
static int column_of(const char *header, const char *name) {
    size_t n = strlen(name);
    const char *p = header;
    for (int col = 0;; col++) {
        size_t len = strcspn(p, ",\r\n");
        if (len == n && strncmp(p, name, n) == 0) {
            return col;
        }
        if (p[len] != ',') {
            return -1;
        }
        p += len + 1;
    }
}

/* Reads the number in column `col` of `row` into `value`; 0 when the field is not a number. */
static int field(const char *row, int col, double *value) {
    const char *p = row;
    for (int i = 0; i < col; i++) {
        p = strchr(p, ',');
        if (p == NULL) {
            return 0;
        }
        p++;
    }
    char *end = NULL;
    *value = strtod(p, &end); /* reads the shortest round-trip text back to the same bits */
    return end != p && (*end == ',' || *end == '\r' || *end == '\n' || *end == '\0');
}

/* Reads one line; 0 at the end of the input, -1 when the line does not fit the buffer. */
static int read_line(void) {
    if (fgets(line, sizeof line, stdin) == NULL) {
        return 0;
    }
    if (strchr(line, '\n') == NULL && !feof(stdin)) {
        return -1;
    }
    return 1;
}

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
    if (read_line() != 1) {
        fprintf(stderr, "hbn-firmware: no header line (expected one naming `u` and `y`, "
                        "such as `u,y` or the header of `hbn estimate --csv`)\n");
        return 1;
    }
    int cu = column_of(line, "u");
    int cy = column_of(line, "y");
    if (cu < 0 || cy < 0) {
        fprintf(stderr, "hbn-firmware: the header line names no `%s` column: %s",
                cu < 0 ? "u" : "y", line);
        return 1;
    }
    printf("x,x_std,flags\n");
    unsigned long row = 1;
    int got;
    while ((got = read_line()) != 0) {
        row++;
        if (got < 0) {
            fprintf(stderr, "hbn-firmware: line %lu is longer than %zu characters\n", row,
                    sizeof line - 2);
            return 1;
        }
        if (line[0] == '\n' || line[0] == '\r' || line[0] == '\0') {
            continue;
        }
        double u, y;
        if (!field(line, cu, &u) || !field(line, cy, &y)) {
            fprintf(stderr, "hbn-firmware: line %lu has no number in column %s: %s", row,
                    field(line, cu, &u) ? "y" : "u", line);
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
