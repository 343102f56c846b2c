/*
 * hbn firmware example for a vector model (several inputs, state components and sensors): the
 * vector estimator step in C, from the files `hbn export --format c` writes for such a model
 * (hbn_model.h, hbn_model.c), the header hbn.h and the static library libhbn_ffi.a.
 *
 * Reads CSV from stdin: a header line that names the columns `u0` .. `u{HBN_MODEL_INPUTS-1}` and
 * `y0` .. `y{HBN_MODEL_SENSORS-1}` (in any order, among other columns), then one row per sample
 * at the model's rate; a sensor field `NaN` is a missing sample. Writes rows
 * `x0,x0_std,x1,x1_std,...,flags` to stdout, one per input row, with a header line: the columns
 * of `hbn estimate --csv` of the same names. No allocation: the filter and its work memory are
 * static, sized by the export (HBN_MODEL_WORK_LEN).
 *
 * Build: make -C examples/firmware-c-vector MODEL=DIR   (DIR holds the exported files)
 * Run:   examples/firmware-c-vector/build/hbn-firmware-vector < samples.csv > firmware.csv
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "hbn.h"
#include "hbn_model.h"

#ifndef HBN_MODEL_VECTOR
#error "hbn_model.h is a scalar model's export: build examples/firmware-c with it instead"
#endif

static HbnVectorFilter filter;
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

/* Finds the columns `prefix0` .. `prefix{n-1}`; 0 (and a message) when one is missing. */
static int columns(const char *prefix, int n, int *cols) {
    char name[16];
    for (int i = 0; i < n; i++) {
        snprintf(name, sizeof name, "%s%d", prefix, i);
        cols[i] = column_of(line, name);
        if (cols[i] < 0) {
            fprintf(stderr, "hbn-firmware-vector: the header line names no `%s` column: %s", name,
                    line);
            return 0;
        }
    }
    return 1;
}

int main(void) {
    size_t needed = hbn_vector_work_len(&hbn_model);
    if (needed == 0 || needed > sizeof work / sizeof work[0]) {
        fprintf(stderr,
                "hbn-firmware-vector: the model needs %zu doubles of work memory, %zu given\n",
                needed, sizeof work / sizeof work[0]);
        return 1;
    }
    HbnStatus status =
        hbn_vector_filter_init(&filter, &hbn_model, work, sizeof work / sizeof work[0]);
    if (status != HBN_STATUS_OK) {
        fprintf(stderr, "hbn-firmware-vector: hbn_vector_filter_init failed: %s\n",
                hbn_status_name(status));
        return 1;
    }
    if (read_line() != 1) {
        fprintf(stderr, "hbn-firmware-vector: no header line (expected one naming u0.. and y0..)\n");
        return 1;
    }
    int cu[HBN_MODEL_INPUTS], cy[HBN_MODEL_SENSORS];
    if (!columns("u", HBN_MODEL_INPUTS, cu) || !columns("y", HBN_MODEL_SENSORS, cy)) {
        return 1;
    }
    for (int i = 0; i < HBN_MODEL_STATES; i++) {
        printf("x%d,x%d_std,", i, i);
    }
    printf("flags\n");
    unsigned long row = 1;
    int got;
    while ((got = read_line()) != 0) {
        row++;
        if (got < 0) {
            fprintf(stderr, "hbn-firmware-vector: line %lu is longer than %zu characters\n", row,
                    sizeof line - 2);
            return 1;
        }
        if (line[0] == '\n' || line[0] == '\r' || line[0] == '\0') {
            continue;
        }
        double u[HBN_MODEL_INPUTS], y[HBN_MODEL_SENSORS];
        for (int a = 0; a < HBN_MODEL_INPUTS; a++) {
            if (!field(line, cu[a], &u[a])) {
                fprintf(stderr, "hbn-firmware-vector: line %lu has no number as u%d: %s", row, a,
                        line);
                return 1;
            }
        }
        for (int j = 0; j < HBN_MODEL_SENSORS; j++) {
            if (!field(line, cy[j], &y[j])) {
                fprintf(stderr, "hbn-firmware-vector: line %lu has no number as y%d: %s", row, j,
                        line);
                return 1;
            }
        }
        HbnVectorOutput out;
        status = hbn_vector_filter_step(&filter, u, y, &out);
        if (status != HBN_STATUS_OK) {
            fprintf(stderr, "hbn-firmware-vector: hbn_vector_filter_step failed: %s\n",
                    hbn_status_name(status));
            return 1;
        }
        /* %.17g prints every double so that it reads back to the same bits. */
        for (int i = 0; i < HBN_MODEL_STATES; i++) {
            printf("%.17g,%.17g,", out.x[i], out.x_std[i]);
        }
        printf("%u\n", (unsigned)out.flags);
    }
    return 0;
}
