/* Minimal replacement for the NDK's crtbegin_so.o (bionic/libc/arch-common/bionic/crtbegin_so.c): the
 * project builds its Android library without the NDK (`cargo xtask apk`). */
extern void __cxa_finalize(void *);
extern int __cxa_atexit(void (*)(void *), void *, void *);
extern int __register_atfork(void (*)(void), void (*)(void), void (*)(void), void *);
__attribute__((visibility("hidden"))) void *__dso_handle = &__dso_handle;

__attribute__((destructor, visibility("hidden"))) void __on_dlclose(void) {
  __cxa_finalize(&__dso_handle);
}
__attribute__((weak, visibility("hidden"))) void __emutls_unregister_key(void) {}
__attribute__((destructor(65535), visibility("hidden"))) void __on_dlclose_late(void) {
  __emutls_unregister_key();
}
/* bionic does not export atexit/pthread_atfork from libc.so; the crt object provides them. */
static void __atexit_handler_wrapper(void *func) { if (func) ((void (*)(void))func)(); }
__attribute__((visibility("hidden"))) int atexit(void (*func)(void)) {
  return __cxa_atexit(__atexit_handler_wrapper, (void *)func, &__dso_handle);
}
__attribute__((visibility("hidden"))) int pthread_atfork(void (*p)(void), void (*pa)(void), void (*c)(void)) {
  return __register_atfork(p, pa, c, &__dso_handle);
}
